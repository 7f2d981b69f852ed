"""The C boundary: one declaration (native.h) that Python reads, checked entry points, and
memory that no public assignment can make C read or write out of bounds."""

import json
import os
import re
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

import numpy as np
import pytest
from conftest import ROOT

from iout_mj import native
from iout_mj.backends.kinematic import move
from iout_mj.mission import Mission, rules
from iout_mj.scenarios import make_config

GUARD = 64
"""Bytes of sentinel before and after every array the rules point to (keeps alignment)."""
SENTINEL = 0xA5
STRAIGHT = (5, 3, 0, 0)  # heading 5: no turn; speed 3: no change; nodes 0 and 0


class GuardedAllocator:
    """`native.allocate` carving every array out of a larger buffer with sentinel bytes on
    both sides, so any write outside an array shows."""

    def __init__(self) -> None:
        self.buffers: list[np.ndarray] = []

    def __call__(self, shape, dtype, fill=0):
        dtype, shape = np.dtype(dtype), tuple(shape)
        nbytes = int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
        raw = np.full(nbytes + 2 * GUARD, SENTINEL, dtype=np.uint8)
        array = raw[GUARD : GUARD + nbytes].view(dtype).reshape(shape)
        array[...] = fill
        self.buffers.append(raw)
        return array

    def intact(self) -> bool:
        return all(
            (r[:GUARD] == SENTINEL).all() and (r[-GUARD:] == SENTINEL).all() for r in self.buffers
        )

    def owns(self, address: int) -> bool:
        """`address` lies in one of the guarded buffers (numpy points an empty array at its
        buffer's start)."""
        return any(
            int(r.ctypes.data) <= address < int(r.ctypes.data) + r.size for r in self.buffers
        )


@pytest.fixture
def guarded(monkeypatch):
    allocator = GuardedAllocator()
    monkeypatch.setattr(native, "allocate", allocator)
    return allocator


def _pointers(struct) -> dict[str, int]:
    """Every pointer field of a view, nested structs included, by dotted name."""
    out = {}
    for f in native.FIELDS[type(struct).__name__]:
        if f.kind == "pointer":
            out[f.name] = getattr(struct, f.name)
        elif f.kind == "struct":
            out.update({f"{f.name}.{k}": v for k, v in _pointers(getattr(struct, f.name)).items()})
    return out


@pytest.mark.parametrize("n_envs", [None, 3])
def test_every_pointer_of_the_view_is_an_owned_guarded_buffer(guarded, n_envs):
    m = Mission(make_config(2, 7), n_envs=n_envs)
    m.reset(np.random.RandomState(0))
    move(m, np.tile(STRAIGHT * 2, (n_envs, 1)) if n_envs else np.array(STRAIGHT * 2))
    pointers = _pointers(m._view)
    own = len(rules.CONSTANTS) + len(rules.INPUTS)  # 7 constants, 14 slot buffers
    assert len(pointers) == sum(len(native.FIELDS[s]) for s in ("State", "Log", "Network")) + own
    assert {k for k, v in pointers.items() if not guarded.owns(v)} == set()
    assert guarded.intact()


@pytest.mark.parametrize(
    ("target", "name"),
    [
        ("mission", "state"),
        ("mission", "network"),
        ("mission", "log"),
        ("mission", "params"),
        ("mission", "n_nodes"),
        ("mission", "term_values"),
        ("mission", "actions"),
        ("state", "positions_m"),
        ("state", "slot"),
        ("log", "positions_m"),
        ("network", "nodes_m"),
        ("network", "link"),
        ("actions", "dtheta_rad"),
        ("link", "constants"),
    ],
)
def test_arrays_the_rules_point_to_cannot_be_rebound(target, name):
    m = Mission(make_config(2, 7))
    obj = {
        "mission": m,
        "state": m.state,
        "log": m.log,
        "network": m.network,
        "actions": m.actions,
        "link": m.network.link,
    }[target]
    with pytest.raises(AttributeError, match=f"{name} cannot be rebound.*in place"):
        setattr(obj, name, np.zeros(100_000))


@pytest.mark.parametrize(
    "array",
    [
        "params",
        "actions.dtheta_rad",
        "actions.dv_mps",
        "network.link.constants",
        "network.channel.constants",
    ],
)
def test_constants_the_rules_read_are_read_only(array):
    m = Mission(make_config(2, 7))
    obj = m
    for part in array.split("."):
        obj = getattr(obj, part)
    with pytest.raises(ValueError, match="read-only"):
        obj[...] = 0


@pytest.mark.parametrize(
    ("attack", "message"),
    [
        (lambda m: m.state.slot.__setitem__(..., -5), r"slot -5; accepted 0 to T_max = 55"),
        (lambda m: m.state.slot.__setitem__(..., 10**9), r"slot 1000000000; accepted 0 to"),
        (lambda m: m.state.slot.__setitem__(..., -(2**62)), r"accepted 0 to T_max"),
    ],
)
@pytest.mark.parametrize("n_envs", [None, 2])
def test_a_slot_out_of_range_is_refused_before_any_write(guarded, attack, message, n_envs):
    m = Mission(make_config(2, 7), n_envs=n_envs)
    m.reset(np.random.RandomState(0))
    attack(m)
    action = np.tile(STRAIGHT * 2, (n_envs, 1)) if n_envs else np.array(STRAIGHT * 2)
    before = m.state.positions_m.copy()
    for call in (lambda: move(m, action), m.observe, lambda: m.begin_slot(action)):
        with pytest.raises(native.NativeError, match=message):
            call()
    np.testing.assert_array_equal(m.state.positions_m, before)
    assert guarded.intact()


def test_an_out_of_range_last_action_in_the_state_is_refused_by_end_slot(guarded):
    m = Mission(make_config(2, 7))
    m.reset(np.random.RandomState(0))
    m.begin_slot(np.array(STRAIGHT * 2))
    m.state.action[1, 3] = 10**6  # the uplink node C would index with
    here = m.state.positions_m.copy()
    zero = np.zeros(2)
    with pytest.raises(native.ActionError, match=r"AUV 1: uplink_node index 1000000 .* 0 to 6"):
        m.end_slot(here, zero, zero, zero, zero, here[None])
    assert int(m.state.slot) == 0 and guarded.intact()


def test_stepping_past_the_horizon_writes_nothing_outside_the_log(guarded):
    m = Mission(make_config(2, 7))
    m.reset(np.random.RandomState(0))
    action = np.array((5, 0, 0, 0) * 2)  # speed index 0: slows to a stop, never docks
    for _ in range(55):
        move(m, action)
    assert m.state.truncated
    for _ in range(3):  # a caller that ignores the end: refused, in bounds
        try:
            move(m, action)
        except native.NativeError as exc:
            assert "accepted 0 to T_max = 55" in str(exc)
    assert guarded.intact()


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (
            lambda: native.lib.iout_link_energies(0, 0, -1, 0, 0),
            "iout_link_energies: count -1",
        ),
        (lambda: native.lib.iout_summarise(0, 0, 7), "0 environments of 7 nodes"),
        (lambda: native.lib.iout_summarise(0, 1, 0), "1 environments of 0 nodes"),
        (lambda: native.lib.iout_unserved_aoi_sum(0, 3, 0, 0, 0), "0 nodes; accepted at least 1"),
        (lambda: native.lib.iout_node_energy_levels(0, -3, 1.0, 2.0, 0), "count -3 < 0"),
    ],
)
def test_every_entry_point_refuses_counts_out_of_range(call, message):
    # null pointers: a refusal must come before C touches any of them
    with pytest.raises(native.NativeError, match=message):
        native.call(call)


# ------------------------------------------------------------------ one declaration
def _build_variant(tmp_path: Path, edit) -> Path:
    """A copy of the package whose library is compiled from an edited native.h."""
    package = tmp_path / "iout_mj"
    shutil.copytree(ROOT / "iout_mj", package, ignore=shutil.ignore_patterns("*.so", "__pycache__"))
    header = package / "native.h"
    header.write_text(edit(header.read_text()))
    sources = [package / "native.c", *sorted(package.glob("*/*.c"))]
    library = package / f"_native{sysconfig.get_config_var('EXT_SUFFIX')}"
    flags = ["-O1", "-std=gnu11", "-fPIC", "-shared", "-fvisibility=hidden"]
    subprocess.run(["gcc", *flags, "-o", library, *sources, "-lm"], check=True)
    return tmp_path


MISSION = """
import json, numpy as np, iout_mj
from iout_mj.backends.kinematic import move
from iout_mj.mission import Mission
from iout_mj.scenarios import make_config
m = Mission(make_config(2, 7))
m.reset(np.random.RandomState(0))
m.state.positions_m[...] = [[800.0, 700.0], [700.0, 800.0]]  # 130 m from the dock
m.state.heading_sp[...] = [np.pi / 2, 0.0]
m.state.speed_sp[...] = 2.0
while not (m.state.terminated or m.state.truncated):
    move(m, np.array([5, 3, 0, 1] * 2))
print(json.dumps({"file": iout_mj.__file__, "docked": m.state.docked.tolist(),
                  "slot": int(m.state.slot), "obs": m.observe().tolist(),
                  "reward": float(m.state.reward), "terms": m.term_values.tolist()}))
"""


def _run(path: Path, code: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-c", code],
        cwd=path,
        env={**os.environ, "PYTHONPATH": str(path)},
        capture_output=True,
        text=True,
    )


def _swap(text: str, a: str, b: str) -> str:
    assert a in text and b in text
    return text.replace(a, "\0").replace(b, a).replace("\0", b)


@pytest.mark.slow
def test_fields_reordered_in_the_header_give_the_same_mission(tmp_path):
    def edit(text: str) -> str:
        text = _swap(text, "X(bool, docked)", "X(bool, terminated)")  # State pointers
        text = _swap(text, "X(double, v_max_mps)", "X(int64_t, k_reset)")  # Params values
        return _swap(text, "X(double, harvest_j)", "X(double, spreading)")  # Link values

    variant = _run(_build_variant(tmp_path, edit), MISSION)
    original = _run(ROOT, MISSION)
    assert variant.returncode == 0, variant.stderr
    a, b = json.loads(original.stdout), json.loads(variant.stdout)
    assert b["file"].startswith(str(tmp_path))
    assert a["docked"] == b["docked"] == [True, True] and a["slot"] == b["slot"]
    assert (a["reward"], a["terms"], a["obs"]) == (b["reward"], b["terms"], b["obs"])


@pytest.mark.slow
@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        (
            "X(double, speed_sp)",
            "X(int64_t, speed_sp)",
            r"declares State .*speed_sp \(float64 here, int64 in C\)",
        ),
        (
            "X(double, jain) /* (B,) */",
            "X(double, jain) X(double, spare_j)",
            r"declares Network .*unknown to Python: \['spare_j'\]",
        ),
        ("X(aoi_after_mission)", "X(aoi_after_mission) X(bonus)", r"reward terms"),
        ("X(time_remaining, 0, 0, 0, 1)", "X(time_left, 0, 0, 0, 1)", r"observation groups"),
    ],
)
def test_a_library_declared_unlike_python_is_refused_at_import(tmp_path, old, new, message):
    def edit(text: str) -> str:
        assert old in text
        text = text.replace(old, new)
        # a new term or group needs its C function to compile: alias an existing one
        return (
            text + "\n#define bonus aoi_after_mission\n#define obs_time_left obs_time_remaining\n"
        )

    out = _run(_build_variant(tmp_path, edit), "import iout_mj.mission")
    assert out.returncode != 0
    assert "ImportError" in out.stderr
    assert re.search(message, out.stderr), out.stderr[-2000:]
