"""Statistics a reviewer accepts: IQM, stratified-bootstrap CIs and the probability of
improvement (rliable) on known samples; `evaluate --training-seeds` and `compare` on small
real evaluations (kinematic, planners, a copied shipped policy as a training seed)."""

import json
import shutil

import numpy as np
import pytest
from rliable import metrics

from iout_mj.agents.shipped import SHIPPED_DIR
from iout_mj.cli import main
from iout_mj.errors import PolicyError, UsageError
from iout_mj.experiments import statistics
from iout_mj.experiments.evaluate import evaluate, seed_variant


def test_the_iqm_of_1_to_8_is_the_mean_of_the_middle_half_with_a_reproducible_ci():
    scores = np.arange(1.0, 9.0)[:, None]
    state = np.random.get_state()
    est = statistics.iqm(scores, seed=3)
    assert est.value == pytest.approx(np.mean([3, 4, 5, 6]))
    assert 1.0 <= est.low < est.value < est.high <= 8.0
    assert statistics.iqm(scores, seed=3) == est  # the seed fixes the bootstrap
    after = np.random.get_state()
    assert all(np.array_equal(a, b) for a, b in zip(state[1:3], after[1:3], strict=True))


def test_the_ci_contains_the_iqm_and_shrinks_with_more_runs():
    rng = np.random.default_rng(0)
    widths = []
    for runs in (10, 400):
        est = statistics.iqm(rng.normal(10.0, 2.0, (runs, 1)))
        assert est.low <= est.value <= est.high
        widths.append(est.high - est.low)
    assert widths[1] < 0.4 * widths[0]  # ~ 1 / sqrt(40) of it


def test_probability_of_improvement_of_known_samples():
    low, high = np.arange(1.0, 9.0)[:, None], np.arange(101.0, 109.0)[:, None]
    poi = lambda x, y: statistics.probability_of_improvement(x, y, reps=500)  # noqa: E731
    same = poi(low, low)
    assert same.value == 0.5
    better = poi(low, high)  # every AoI lower
    assert (better.value, better.low, better.high) == (1.0, 1.0, 1.0)
    assert poi(high, low).value == 0.0
    # x < y in 3 of the 4 pairs (1<2, 1<4, 3<4; not 3<2)
    partial = poi(np.array([[1.0], [3.0]]), np.array([[2.0], [4.0]]))
    assert partial.value == 0.75


def test_per_cell_estimates_are_rliables_on_each_cell_and_their_average():
    rng = np.random.default_rng(1)
    aoi = [rng.normal(10.0, 1.0, 6) for _ in range(3)]
    ref = [rng.normal(10.5, 1.0, 4) for _ in range(3)]
    iqms = statistics.cells_iqm(aoi, reps=200)
    assert [e.value for e in iqms] == pytest.approx([metrics.aggregate_iqm(a) for a in aoi])
    each, mean = statistics.cells_improvement(aoi, ref, reps=200)
    want = [
        metrics.probability_of_improvement(-a[:, None], -r[:, None])
        for a, r in zip(aoi, ref, strict=True)
    ]
    assert [e.value for e in each] == pytest.approx(want)
    assert mean.value == pytest.approx(
        metrics.probability_of_improvement(-np.stack(aoi, 1), -np.stack(ref, 1))
    )
    with pytest.raises(UsageError, match="its cells hold 5, 6 runs: accepted cells evaluated"):
        statistics.normalised_iqm([aoi[0], aoi[1][:5]], ref[:2])


def test_seed_variants_resolve_like_the_policy(tmp_path):
    assert seed_variant("ppo-general", 0, 2) == "ppo-general"
    assert seed_variant("ppo-general", 3, 2) == "ppo-general-n2-seed3"
    assert seed_variant("ppo-n1-k7", 2, 1) == "ppo-n1-k7-seed2"
    assert seed_variant("runs/gen/", 1, 1) == "runs/gen-seed1"
    # a run folder named for seed 0 (train --seed 0): its seed is replaced
    assert seed_variant("runs/gen-seed0/best", 2, 2) == "runs/gen-seed2/best"
    assert seed_variant("runs/gen-seed0", 1, 2) == "runs/gen-seed1"
    shutil.copytree(SHIPPED_DIR / "ppo-n1-k7", tmp_path / "gen")
    manifest = str(tmp_path / "gen" / "policy.json")
    assert seed_variant(manifest, 4, 1) == str(tmp_path / "gen-seed4" / "policy.json")


@pytest.fixture
def run(capsys, monkeypatch):
    """`iout-mj ARGS` in this process (imports paid once): (exit code, stdout, stderr)."""
    monkeypatch.setenv("TQDM_DISABLE", "1")

    def call(*args):
        code = main([str(a) for a in args])
        out = capsys.readouterr()
        return code, out.out, out.err

    return call


def test_training_seeds_fly_each_seed_under_the_policys_name(tmp_path, run):
    """Seed 0 is the folder itself, seed 1 the folder `-seed1` (here another shipped policy,
    so its episodes differ and must equal that policy's own); baselines fly once."""
    shutil.copytree(SHIPPED_DIR / "ppo-n1-k7", tmp_path / "pol")
    shutil.copytree(SHIPPED_DIR / "ppo-general-n1", tmp_path / "pol-seed1")
    pol = str(tmp_path / "pol")
    args = ("evaluate", "--policy", pol, "greedy", "--n-auvs", "1", "--nodes", "7")
    args += ("--episodes", "1", "--backend", "kinematic", "--workers", "1")
    code, _, _ = run(*args, "--training-seeds", "0", "1", "--out", tmp_path / "r")
    assert code == 0
    episodes = json.loads((tmp_path / "r" / "episodes.json").read_text())
    by = {(e["policy"], e["training_seed"]): e for e in episodes}
    assert len(episodes) == 3 and set(by) == {("greedy", None), (pol, 0), (pol, 1)}
    _, (general,) = evaluate(["ppo-general-n1"], [1], [7], 1, 0, "kinematic", progress=False)
    assert by[(pol, 1)]["mean_aoi_horizon"] == general["mean_aoi_horizon"]
    assert by[(pol, 1)]["mean_aoi_horizon"] != by[(pol, 0)]["mean_aoi_horizon"]
    rows = {r["policy"]: r for r in json.loads((tmp_path / "r" / "results.json").read_text())}
    assert (rows[pol]["training_seeds"], rows[pol]["episodes"]) == (2, 2)
    assert (rows["greedy"]["training_seeds"], rows["greedy"]["episodes"]) == (0, 1)
    aoi = [by[(pol, k)]["mean_aoi_horizon"] for k in (0, 1)]
    assert rows[pol]["mean_aoi_horizon"] == pytest.approx(np.mean(aoi))  # seeds pooled

    code, _, err = run(*args, "--training-seeds", "0", "2", "--out", tmp_path / "missing")
    assert code == 2
    assert f"training seed 2 of {pol!r} at N=1, K=7 is the policy '{pol}-seed2'" in err
    assert "unknown policy" in err and "a policy folder" in err  # what is accepted
    assert not (tmp_path / "missing" / "episodes.json").exists()  # refused before any episode


def test_training_seed_0_writes_todays_rows_plus_the_column():
    args = (["greedy", "ppo-n1-k7"], [1], [7], 2, 5, "kinematic")
    rows, episodes = evaluate(*args, workers=1, progress=False)
    again, same = evaluate(*args, workers=1, progress=False, training_seeds=[0])
    assert (again, same) == (rows, episodes)
    keys = ["policy", "n_auvs", "n_nodes", "layout", "seed", "training_seed", "backend"]
    assert all(list(e)[:7] == keys for e in episodes)
    assert [(e["policy"], e["seed"], e["training_seed"]) for e in episodes] == [
        ("greedy", 5, None),
        ("greedy", 6, None),
        ("ppo-n1-k7", 5, 0),
        ("ppo-n1-k7", 6, 0),
    ]
    assert [r["training_seeds"] for r in rows] == [0, 1]
    with pytest.raises(PolicyError, match="'ppo-n1-k7-seed1'"):
        evaluate(["ppo-n1-k7"], [1], [7], 1, 0, "kinematic", progress=False, training_seeds=[0, 1])
    with pytest.raises(UsageError, match="training seed 1 given more than once"):
        evaluate(["greedy"], [1], [7], 1, 0, "kinematic", training_seeds=[1, 1])


@pytest.fixture(scope="module")
def planners(tmp_path_factory):
    """A small real evaluation: three planners, N = 1 and 2, K = 5, 2 episodes, kinematic."""
    out = tmp_path_factory.mktemp("planners")
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("TQDM_DISABLE", "1")
        code = main(
            [
                *("evaluate", "--policy", "greedy", "planner", "tour-scheduler", "--n-auvs"),
                *("1", "2", "--nodes", "5", "--episodes", "2", "--backend", "kinematic"),
                *("--workers", "1", "--out", str(out)),
            ]
        )
    assert code == 0
    return out


def _runs(folder, policy):
    episodes = json.loads((folder / "episodes.json").read_text())
    out: dict = {}
    for e in episodes:
        if e["policy"] == policy:
            out.setdefault(e["n_auvs"], []).append(e["mean_aoi_horizon"])
    return {n: np.array(v) for n, v in out.items()}


def test_compare_per_cell_and_aggregate_on_a_real_evaluation(planners, run):
    code, out, _ = run("compare", "--results", planners, "--policy", "greedy", "--json")
    assert code == 0
    result = json.loads(out)
    mine, ref = _runs(planners, "greedy"), _runs(planners, "tour-scheduler")
    assert [c["n_auvs"] for c in result["cells"]] == [1, 2]
    for cell in result["cells"]:
        n = cell["n_auvs"]
        assert cell["reference"] == "tour-scheduler"
        assert cell["policy_aoi_iqm"] == pytest.approx(mine[n].mean())  # 2 runs: nothing trimmed
        assert cell["reference_aoi_iqm"] == pytest.approx(ref[n].mean())
        assert cell["ratio"] == pytest.approx(mine[n].mean() / ref[n].mean())
        pairs = [a < b for a in mine[n] for b in ref[n]]
        assert cell["p_improvement"] == pytest.approx(np.mean(pairs))
        assert cell["policy_aoi_iqm_low"] <= cell["policy_aoi_iqm"] <= cell["policy_aoi_iqm_high"]
    total = result["aggregate"]
    normalised = np.stack([mine[n] / ref[n].mean() for n in (1, 2)], axis=1)
    assert total["normalised_aoi_iqm"] == pytest.approx(np.mean(np.sort(normalised.ravel())[1:3]))
    want = np.mean([c["p_improvement"] for c in result["cells"]])
    assert total["p_improvement"] == pytest.approx(want)
    assert (total["cells"], total["runs_per_cell"], total["episodes"]) == (2, 2, 2)
    assert result["bootstrap"] == {"method": "stratified", "reps": 2000, "seed": 0}

    code, table, _ = run("compare", "--results", planners, "--policy", "greedy")
    lines = table.splitlines()
    assert lines[0].startswith("| N | K | greedy IQM AoI(Tmax) [95 % CI] | tour-scheduler IQM")
    cell = result["cells"][0]
    low, iqm, high = (cell[f"policy_aoi_iqm{s}"] for s in ("_low", "", "_high"))
    assert lines[2].startswith(f"| 1 | 5 | {iqm:.2f} [{low:.2f}, {high:.2f}] |")
    assert lines[-1].startswith("aggregate over 2 cells: IQM of AoI(Tmax) / tour-scheduler's")
    assert "greedy: 2 episodes, no training seeds = 2 runs per cell" in lines[-1]
    assert "95 % CIs by stratified bootstrap (2,000 resamples, seed 0; rliable)" in lines[-1]


def test_compare_against_the_best_planner_of_every_cell(planners, run):
    args = ("compare", "--results", planners, "--policy", "greedy", "--reference")
    code, out, _ = run(*args, "best-planner", "--bootstrap-reps", "200", "--json")
    assert code == 0
    rows = json.loads((planners / "results.json").read_text())
    for cell in json.loads(out)["cells"]:
        others = [
            r
            for r in rows
            if r["n_auvs"] == cell["n_auvs"] and r["policy"] in ("planner", "tour-scheduler")
        ]
        best = min(others, key=lambda r: r["mean_aoi_horizon"])
        assert cell["reference"] == best["policy"]
        assert cell["reference_aoi_iqm"] == pytest.approx(best["mean_aoi_horizon"])
    code, table, _ = run(*args, "best-planner", "--bootstrap-reps", "200")
    assert "| N | K | best planner | greedy IQM" in table
    assert "P(greedy < the best planner)" in table.splitlines()[-1]
    code, _, err = run(*args, "ppo-general", "--bootstrap-reps", "200")
    assert code == 2 and "no cell holds both 'greedy' and 'ppo-general'" in err


def test_compare_reads_policies_evaluated_apart(planners, tmp_path, run):
    """A policy and its reference from two evaluations read as one (the same episodes)."""
    for policy in ("greedy", "tour-scheduler"):
        code, _, _ = run(
            *("evaluate", "--policy", policy, "--n-auvs", "1", "--nodes", "5", "--episodes"),
            *("2", "--backend", "kinematic", "--workers", "1", "--out", tmp_path / policy),
        )
        assert code == 0
    args = ("--policy", "greedy", "--bootstrap-reps", "200", "--json")
    apart_folders = (tmp_path / "greedy", tmp_path / "tour-scheduler")
    code, out, _ = run("compare", "--results", *apart_folders, *args)
    assert code == 0
    apart = json.loads(out)["cells"]
    code, out, _ = run("compare", "--results", planners, *args)
    together = [c for c in json.loads(out)["cells"] if c["n_auvs"] == 1]
    keys = ("policy_aoi_iqm", "reference_aoi_iqm", "ratio", "p_improvement", "reference")
    assert [[c[k] for k in keys] for c in apart] == [[c[k] for k in keys] for c in together]
    code, _, err = run("compare", "--results", tmp_path / "greedy", planners, *args)
    assert code == 2 and "both hold 'greedy' at N=1, K=5" in err


def test_compare_pools_training_seeds_evaluated_apart(planners, tmp_path, run):
    """A learned policy's training seeds evaluated one folder each compare as the same seeds
    evaluated together; the same seed twice, or seeds under other conditions, are refused."""
    shutil.copytree(SHIPPED_DIR / "ppo-general-n1", tmp_path / "pol")
    shutil.copytree(SHIPPED_DIR / "ppo-general-n1-curriculum", tmp_path / "pol-seed1")
    pol = str(tmp_path / "pol")
    flown = ("--n-auvs", "1", "--nodes", "5", "--episodes", "2", "--backend", "kinematic")

    def evaluate_seeds(out, *seeds, config=()):
        code, _, _ = run(
            *("evaluate", "--policy", pol, *flown, "--workers", "1", "--training-seeds"),
            *seeds,
            *config,
            "--out",
            tmp_path / out,
        )
        assert code == 0
        return tmp_path / out

    together, seed0, seed1 = (
        evaluate_seeds("both", "0", "1"),
        evaluate_seeds("s0", "0"),
        evaluate_seeds("s1", "1"),
    )
    args = ("--policy", pol, "--reference", "best-planner", "--bootstrap-reps", "200", "--json")
    results = []
    for folders in ((together, planners), (seed0, seed1, planners)):
        code, out, _ = run("compare", "--results", *folders, *args)
        assert code == 0
        results.append(json.loads(out))
    (cell,), (pooled,) = (r["cells"] for r in results)
    numbers = {k for k, v in cell.items() if isinstance(v, float)}
    assert {k: pooled[k] for k in numbers} == pytest.approx({k: cell[k] for k in numbers})
    assert {k: pooled[k] for k in cell.keys() - numbers} == {
        k: cell[k] for k in cell.keys() - numbers
    }
    assert pooled["policy_docked"] in (0.0, 0.25, 0.5, 0.75, 1.0)  # 4 runs
    assert results[1]["aggregate"] == results[0]["aggregate"]
    assert results[1]["aggregate"]["training_seeds"] == 2

    code, _, err = run("compare", "--results", seed0, together, planners, *args)
    assert code == 2 and f"both hold {pol!r} at N=1, K=5 (seeds [0])" in err
    wenz = evaluate_seeds("wenz", "1", config=("--config", "training/configs/env/wenz.yaml"))
    code, _, err = run("compare", "--results", seed0, wenz, planners, *args)
    assert code == 2 and "under other conditions (noise_model)" in err


def test_compare_grid_puts_conditions_side_by_side(planners, tmp_path, run):
    """Each folder a condition: per cell every policy's IQM ratio and the first one's data share,
    the same numbers `compare` gives folder by folder."""
    wenz = tmp_path / "wenz"
    code, _, _ = run(
        *("evaluate", "--policy", "greedy", "planner", "tour-scheduler", "--n-auvs", "1", "2"),
        *("--nodes", "5", "--episodes", "2", "--backend", "kinematic", "--workers", "1"),
        *("--config", "training/configs/env/wenz.yaml", "--out", wenz),
    )
    assert code == 0
    args = ("--reference", "best-planner", "--bootstrap-reps", "200")
    policies = ("--policy", "greedy", "planner")
    code, out, _ = run("compare", "--results", planners, wenz, *policies, *args, "--grid", "--json")
    assert code == 0
    found = json.loads(out)
    assert [c["results"] for c in found["columns"]] == [str(planners), str(wenz)]
    alone = {}
    for folder in (planners, wenz):
        for policy in ("greedy", "planner"):
            code, out, _ = run("compare", "--results", folder, "--policy", policy, *args, "--json")
            alone[folder, policy] = json.loads(out)
    for column, folder in zip(found["columns"], (planners, wenz), strict=True):
        assert column["comparisons"] == [alone[folder, p] for p in ("greedy", "planner")]

    code, table, _ = run("compare", "--results", planners, wenz, *policies, *args, "--grid")
    lines = table.splitlines()
    assert lines[0] == f"| N | K | layout | backend | {planners.name} | wenz |"

    def entry(folder):
        greedy, planner = (alone[folder, p]["cells"][1] for p in ("greedy", "planner"))
        share = 100 * greedy["policy_mbit"] / greedy["reference_mbit"]
        return f"{greedy['ratio']:.3f} / {planner['ratio']:.3f}, {share:.1f} %"

    assert lines[3] == f"| 2 | 5 | paper | kinematic | {entry(planners)} | {entry(wenz)} |"
    below = sum(c["ratio"] < 1 for c in alone[wenz, "greedy"]["cells"])
    normalised = alone[wenz, "greedy"]["aggregate"]["normalised_aoi_iqm"]
    assert f"wenz: aggregate {normalised:.2f} [" in table
    assert f"greedy below the best planner in {below} of 2 cells on the IQM" in table

    code, _, err = run("compare", "--results", planners, *policies, *args)
    assert code == 2 and "--policy names 2 policies: accepted one, or several with --grid" in err
