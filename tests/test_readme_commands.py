"""Every `iout-mj` command of the README runs, in the order the README gives them within groups of
commands that share a run or output folder (the groups are independent tests), shortened for CI:
one episode per cell, the first and last N and two training seeds on the kinematic model, a
few slots of video, a smoke training of the same kind (`shortened` says exactly what changes;
`train-marl` trains smoke-mappo.yaml). A `--resume` runs after the run it resumes; a training
the README shows twice into one run folder starts it again (--overwrite); a training that
differs from one already run only in its seed and run folder loads its own config and copies
that run; the `bench` lines format the shipped run (benchmarks/results-2cpu.json; `test_cli`
measures `bench --quick`) and `bench --warp` runs quick at B = 1."""

import re
import shlex
import shutil
import sys
from pathlib import Path

import pytest
from conftest import ROOT

pytestmark = pytest.mark.slow

PLACEHOLDERS = ("DIR", "RUN")
"""Commands the README gives as a pattern (`figures --results DIR`) are only parsed."""
TRAININGS = {
    "ppo-general": "smoke-general.yaml",
    "ppo-": "smoke.yaml",
    "mappo-": "smoke-mappo.yaml",
    "ippo-": "smoke-mappo.yaml",
}
"""A README training config -> the smoke config of the same policy kind (tokens, MLP, team)."""


def readme_commands() -> list[list[str]]:
    """Every `iout-mj ...` of the README (inline, or a `.venv/bin/iout-mj` line), in order."""
    text = (ROOT / "README.md").read_text()
    pattern = r"`iout-mj ([^`]+)`|^\.venv/bin/iout-mj ([^#\n]+)"
    found = [a or b for a, b in re.findall(pattern, text, flags=re.M)]
    return [shlex.split(c) for c in found if "--help" not in c]


def _option(argv: list[str], flag: str) -> int | None:
    return argv.index(flag) if flag in argv else None


def _values_end(argv: list[str], i: int) -> int:
    j = i + 1
    while j < len(argv) and not argv[j].startswith("--"):
        j += 1
    return j


def shortened(argv: list[str]) -> list[str]:
    """The same command with CI-sized counts: the kinematic model for evaluations, one episode
    per cell, one K, the first and last N, at most two training seeds and at most 16 search
    candidates per slot (the default), in this process (tests of `evaluate` cover its worker
    pool), 3 slots of a small video, 128 training steps of the smoke config of the same kind
    (into the run folder the README's config would use), 200 bootstrap resamples per
    confidence interval, benchmarks as above."""
    a = [re.sub(r"\+rollout(\d+)$", _at_most_16, t) for t in argv]  # compare's names too
    command = a[0]
    i = _option(a, "--episodes")
    if i is not None:
        a[i + 1] = "1"
    for flag in ("--nodes", "--n-nodes"):
        i = _option(a, flag)
        if i is not None:
            del a[i + 2 : _values_end(a, i)]
    if command == "evaluate":
        i = _option(a, "--training-seeds")
        if i is not None:  # two seeds resolve P-seed<k> as five do, at 2/5 of the episodes
            del a[i + 3 : _values_end(a, i)]
        i = _option(a, "--n-auvs")
        if i is not None:  # the smallest and largest team (`test_cli` flies every N)
            del a[i + 2 : _values_end(a, i) - 1]
        i = _option(a, "--backend")
        a = a[:i] + a[i + 2 :] if i is not None else a
        a += (
            ["--backend", "kinematic", "--episodes", "1"]
            if "--episodes" not in a
            else ["--backend", "kinematic"]
        )
        if "--workers" not in a and "--ray" not in a:
            a += ["--workers", "1"]  # in this process: a pool's start costs more than the episodes
    if command in ("mission", "render"):
        i = _option(a, "--slots")
        a = a[:i] + a[i + 2 :] if i is not None else a
        a += ["--slots", "3"]
        for flag, value in (("--width", "320"), ("--height", "180")):
            i = _option(a, flag)
            a = a[:i] + a[i + 2 :] if i is not None else a
            a += [flag, value]
    if command in ("train", "train-marl"):
        name = a[1].rsplit("/", 1)[-1].removesuffix(".yaml")
        marl = command == "train-marl"
        kind = (
            "smoke-mappo.yaml"
            if marl
            else next(v for k, v in TRAININGS.items() if name.startswith(k))
        )
        a[1] = f"training/configs/{kind}"
        if "--out" not in a:
            seed = a[_option(a, "--seed") + 1] if "--seed" in a else None
            a += ["--out", f"runs/{name}" + (f"-seed{seed}" if seed else "")]
        steps = "256" if marl else "128"
        if "--steps" in a:
            a[_option(a, "--steps") + 1] = steps
        else:
            a += ["--steps", steps]
        n_auvs = re.search(r"-n(\d)\b", name)  # the smoke run flies the README config's N
        if n_auvs and "--n-auvs" not in a and not marl:
            a += ["--n-auvs", n_auvs.group(1)]
    if command == "compare" and "--bootstrap-reps" not in a:
        a += ["--bootstrap-reps", "200"]
    if command == "bench":
        if "--warp" in a:
            pytest.importorskip("mujoco_warp")
            i = _option(a, "--warp-sizes")
            a = (a[:i] + a[_values_end(a, i) :]) if i is not None else a
            a += ["--warp-sizes", "1", "--quick"]
        elif "--from-json" not in a:  # the shipped run formatted (test_cli measures --quick)
            a += ["--from-json", "benchmarks/results-2cpu.json"]
    return a


def _at_most_16(found: re.Match[str]) -> str:
    """`+rollout<C>` with C capped at 16 (the search's cost grows with C)."""
    return f"+rollout{min(int(found.group(1)), 16)}"


def _same_training(argv: list[str]) -> tuple[str, ...]:
    """A shortened training without its seed, run folder and --overwrite."""
    drop = {_option(argv, f) for f in ("--seed", "--out")} - {None}
    skip = drop | {i + 1 for i in drop}
    return tuple(x for i, x in enumerate(argv) if i not in skip and x != "--overwrite")


def test_shortening_keeps_the_command_and_its_options():
    argv = shlex.split(
        "evaluate --policy greedy --n-auvs 1 2 --nodes 3 5 7 --episodes 20 --backend mujoco --out r"
    )
    assert shortened(argv) == shlex.split(
        "evaluate --policy greedy --n-auvs 1 2 --nodes 3 --episodes 1 --out r"
        " --backend kinematic --workers 1"
    )
    marl = shortened(shlex.split("train-marl training/configs/mappo-n3.yaml"))
    assert marl == shlex.split(
        "train-marl training/configs/smoke-mappo.yaml --out runs/mappo-n3 --steps 256"
    )
    seeds = shortened(
        shlex.split(
            "evaluate --policy runs/x/best ppo-general+rollout1024 ppo-general+rollout8"
            " --training-seeds 0 1 2 3 4 --n-auvs 1 2 3 4"
        )
    )
    assert seeds == shlex.split(
        "evaluate --policy runs/x/best ppo-general+rollout16 ppo-general+rollout8"
        " --training-seeds 0 1 --n-auvs 1 4 --backend kinematic --episodes 1 --workers 1"
    )
    train = shortened(shlex.split("train training/configs/ppo-general-n2.yaml --seed 1"))
    smoke = "training/configs/smoke-general.yaml"
    assert train == [
        "train",
        smoke,
        *shlex.split("--seed 1 --out runs/ppo-general-n2-seed1 --steps 128 --n-auvs 2"),
    ]


SHARED_FOLDERS = ("renders", "runs")
"""Output folders many commands write into: only a command naming the folder itself joins them."""


def _resource(token: str) -> str:
    """The run or output folder a token names: any seed of a run, and its `best/`, `last/`,
    `policy/` or `+dock`-style variants, count as the run."""
    t = re.sub(r"\+.*$", "", token).rstrip("/")
    t = re.sub(r"/(best|last|policy)$", "", t)
    return re.sub(r"-seed\d+", "-seed*", t)


def runnable_commands() -> list[list[str]]:
    """The README's commands that are not patterns, as written."""
    return [a for a in readme_commands() if not any(p in a for p in PLACEHOLDERS)]


def readme_groups() -> list[list[int]]:
    """The runnable README commands (indices into `runnable_commands()`) in independent
    groups, README order inside each: commands that name one run or output folder share a
    group, and so do all that start a Ray instance; the groups run as separate tests, in
    parallel under pytest-xdist."""
    commands = [shortened(a) for a in runnable_commands()]
    outs = {_resource(c[_option(c, "--out") + 1]) for c in commands if "--out" in c}
    groups: list[tuple[set[str], list[int]]] = []
    for i, command in enumerate(commands):
        tokens = {_resource(t) for t in command if not t.startswith("--")}
        uses = {
            o
            for o in outs
            for t in tokens
            if t == o or (o not in SHARED_FOLDERS and t.startswith(o + "/"))
        }
        if "--ray" in command or command[0] == "sweep":
            uses.add("ray")
        if command[0] == "bench":  # the README's `bench --warp` lines shorten to one command
            uses.add("bench")
        joined = [g for g in groups if g[0] & uses]
        merged = sorted(j for g in joined for j in g[1])
        for g in joined:
            groups.remove(g)
            uses |= g[0]
        groups.append((uses, [*merged, i]))
    return [g[1] for g in groups]


def test_readme_groups_keep_a_run_with_the_commands_that_read_it():
    groups = readme_groups()
    commands = [shortened(a) for a in runnable_commands()]
    assert sorted(i for g in groups for i in g) == list(range(len(commands)))
    where = {tuple(commands[i]): n for n, g in enumerate(groups) for i in g}
    seeds = "runs/seeds/ppo-n2-k7-seed"
    trainings = [g for c, g in where.items() if c[0] == "train" and seeds in " ".join(c)]
    evaluation = [g for c, g in where.items() if c[0] == "evaluate" and seeds in " ".join(c)]
    assert len(set(trainings + evaluation)) == 1 and len(trainings) == 5  # every seed it reads
    ray = {g for c, g in where.items() if "--ray" in c or c[0] == "sweep"}
    assert len(ray) == 1  # one Ray instance at a time


COMMANDS = runnable_commands()
GROUPS = readme_groups()


@pytest.mark.parametrize(
    "group", GROUPS, ids=[f"{n:02d}-{COMMANDS[g[0]][0]}-{len(g)}" for n, g in enumerate(GROUPS)]
)
def test_every_readme_command_runs_shortened(group: list[int], tmp_path, monkeypatch):
    """In a scratch folder holding the project's training/ and benchmarks/ files, so that the
    README's relative paths work and nothing it writes touches the checkout; in this process
    (`cli.main`, as the console script calls it), so the imports are paid once per worker."""
    from iout_mj.cli import main

    monkeypatch.chdir(tmp_path)
    shutil.copytree(ROOT / "training", tmp_path / "training")
    shutil.copytree(ROOT / "benchmarks", tmp_path / "benchmarks")
    done: set[tuple[str, ...]] = set()
    trained: dict[tuple[str, ...], Path] = {}  # a smoke training -> its run folder
    for argv in (COMMANDS[i] for i in group):
        short = shortened(argv)
        if "--resume" in short:  # the run it resumes comes first (once)
            first = [x for x in short if x != "--resume"]
            if tuple(first) not in done:
                assert main(first) == 0, f"iout-mj {' '.join(first)}"
                done.add(tuple(first))
        if tuple(short) in done:  # the README shows some commands twice
            continue
        done.add(tuple(short))
        again = short[0] == "train" and "--resume" not in short
        if again:
            out = tmp_path / short[_option(short, "--out") + 1]
            earlier = trained.get(_same_training(short))
            if earlier is not None and earlier != out:  # another seed of a run already made
                from iout_mj.training import TrainConfig

                TrainConfig.load(argv[1])
                shutil.copytree(earlier, out, dirs_exist_ok=True)
                continue
            if out.exists():
                short.append("--overwrite")  # a second training into one run folder starts again
            trained[_same_training(short)] = out
        assert main(short) == 0, f"iout-mj {' '.join(short)} (README: {' '.join(argv)})"


def test_the_other_commands_of_the_readme_exist_in_the_environment():
    """The README's non-`iout-mj` shell lines name programs the project's install provides."""
    text = (ROOT / "README.md").read_text()
    blocks = re.findall(r"^```bash\n(.*?)^```", text, flags=re.S | re.M)
    programs = {
        line.split()[0]
        for block in blocks
        for line in block.splitlines()
        if line.strip() and not line.startswith("#")
    }
    for program in programs - {"make", "cat"}:
        assert program.startswith(".venv/bin/"), f"{program}: name it from .venv/bin"
        assert (Path(sys.executable).parent / program.removeprefix(".venv/bin/")).exists()
