"""validate-energy tests the speeds the config can reach: its grid comes from V_max."""

import dataclasses
import itertools
import re
from pathlib import Path

import numpy as np
import pytest

from iout_mj.backends.mujoco.physics import AUVPhysics
from iout_mj.config import Config
from iout_mj.experiments.energy_validation import (
    maneuvers,
    run_maneuver,
    steady_state,
    validate_vehicle,
)
from iout_mj.scenarios import make_config


def with_v_max(v_max_mps: float):
    cfg = make_config(1, 7)
    return cfg.replace(motion=dataclasses.replace(cfg.motion, v_max_mps=v_max_mps))


def test_a_slower_vehicle_is_tested_up_to_its_own_v_max_and_the_model_holds_there():
    rows = steady_state(with_v_max(2.0))
    assert [r["speed_mps"] for r in rows] == [0.25, 0.5, 0.75, 1.0, 1.25, 1.5, 1.75, 2.0]
    for r in rows:  # reached, so the gap is the model's, not the thrust limit's
        assert r["measured_speed_mps"] == pytest.approx(r["speed_mps"], rel=0.01)
        assert abs(r["rel_error"]) <= 0.02, r


@pytest.mark.parametrize("v_max_mps", [1.0, 2.0, 4.0])
def test_every_manoeuvre_stays_within_v_max_and_reaches_it(v_max_mps):
    mans = maneuvers(with_v_max(v_max_mps))
    for man in mans:
        assert max(man.speed_mps) <= v_max_mps and man.start_speed_mps <= v_max_mps, man.name
    assert max(max(m.speed_mps) for m in mans) == v_max_mps
    ramp = next(m for m in mans if m.name == "accelerate 0.4 m/s per slot")
    assert ramp.speed_mps[-1] == v_max_mps and all(
        0 < b - a <= 0.4 + 1e-9 for a, b in itertools.pairwise((0.0, *ramp.speed_mps))
    )


def test_the_ramp_of_a_1_mps_vehicle_ends_at_1_mps():
    ramp = maneuvers(with_v_max(1.0))[1]
    assert ramp.speed_mps == (0.4, 0.8, 1.0)


README = Path(__file__).parents[1] / "README.md"


def _readme_row(first_cell: str) -> list[str]:
    """The cells of the README table row that starts with `first_cell`."""
    for line in README.read_text().splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if cells and cells[0] == first_cell:
            return cells
    raise AssertionError(f"no README table row starts with {first_cell!r}")


def _percent(text: str) -> float:
    return float(re.search(r"([+-]?\d+\.\d) %", text).group(1)) / 100


@pytest.mark.slow
def test_the_readme_energy_headline_is_what_validate_energy_measures_on_the_remus():
    """The README's headline numbers for the cubic model against the REMUS 100 (and its
    published-data table) are the command's output, rounded as printed."""
    result = validate_vehicle(Config().with_vehicle("remus100"))
    mission = next(r for r in result["maneuvers"] if r["name"].startswith("mission"))
    paper = next(r for r in result["paper_cd_s"]["maneuvers"] if r["name"].startswith("mission"))
    row = _readme_row("a planner's whole mission (K = 7, 51 slots)")
    assert mission["slots"] == 51
    assert _percent(row[1]) == pytest.approx(mission["rel_error_path"], abs=5e-4)
    assert _percent(row[2]) == pytest.approx(paper["rel_error_path"], abs=5e-4)
    by_name = {r["quantity"]: r for r in result["published"]}
    turn = _readme_row("rudder +4 deg: turning diameter (m)")
    measured = by_name["rudder +4 deg: turning diameter, m"]["mujoco"]
    assert float(turn[1]) == pytest.approx(measured, abs=0.05)


def test_the_validation_flies_one_auv_whatever_the_config_s_n():
    """A two-AUV config measures one vehicle's power, not the sum over two stacked hulls."""
    one, two = (steady_state(make_config(n, 7), (2.0,))[0] for n in (1, 2))
    assert two["measured_power_w"] == pytest.approx(one["measured_power_w"], rel=1e-9)
    assert abs(one["rel_error"]) < 0.02


def test_physics_refuses_one_auv_s_pose_for_two_naming_the_shape():
    physics = AUVPhysics.from_config(make_config(2, 7))
    with pytest.raises(ValueError, match=r"xy_m has shape \(1, 2\); accepted: \(2, 2\)"):
        physics.set_poses(np.array([[1.0, 2.0]]), np.zeros(2), np.zeros(2))
    with pytest.raises(ValueError, match=r"speed_setpoint_mps has shape \(1,\); accepted: \(2,\)"):
        physics.set_commands(np.zeros(2), np.ones(1))
    physics.free()


def test_the_replayed_mission_flies_in_open_water():
    """The REMUS's replay of a planner's mission drifts south of the scenario's area; the
    validation lets it (no fence), so its energy is the hull's alone."""
    cfg = Config().with_vehicle("remus100")
    (man,) = [m for m in maneuvers(cfg) if m.name.startswith("mission")]
    ends = run_maneuver(cfg, man, cfg.physics.timestep_s)["end_m"]
    assert ends[:, 1].min() < -10.0  # beyond the south edge, where the fence would stop it
