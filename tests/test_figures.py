"""`figures`: every figure it can draw, each one it cannot said with the reason; titles with
the condition; 95 % confidence intervals clipped to the measure's range."""

import json
import math
import struct

import pytest

from iout_mj.errors import UsageError
from iout_mj.experiments import figures
from iout_mj.mission.stats import SUMMARY_KEYS


def row(policy, n_auvs, n_nodes, **changes):
    r = {"policy": policy, "n_auvs": n_auvs, "n_nodes": n_nodes, "layout": "random"}
    r |= {"backend": "mujoco", "episodes": 3}
    for i, key in enumerate(SUMMARY_KEYS):
        r[key], r[key + "_std"] = 10.0 + i, 0.5
    r["jain"], r["jain_std"] = 0.98, 0.05
    return r | changes


def trace(n_auvs):
    return {
        "positions_m": [[[50.0, 50.0]] * n_auvs, [[60.0, 50.0]] * n_auvs],
        "headings_rad": [[0.0] * n_auvs, [0.1] * n_auvs],
        "speeds_mps": [[1.0] * n_auvs, [1.5] * n_auvs],
        "nodes_m": [[100.0, 100.0], [800.0, 500.0], [500.0, 900.0]],
        "delivered_bits_per_node": [12000.0, 0.0, 3000.0],
        "dock_center_m": [830.0, 830.0],
        "dock_radius_m": 70.0,
        "area_m": [1000.0, 1000.0],
        "slot_s": 25.0,
    }


def results(folder, rows, traces=None):
    folder.mkdir()
    (folder / "results.json").write_text(json.dumps(rows))
    if traces is not None:
        (folder / "traces.json").write_text(json.dumps(traces))
    return folder


GRID = [row(p, n, k) for p in ("greedy", "ppo") for n in (1, 2) for k in (3, 11, 20)]


@pytest.mark.parametrize(
    ("traces", "said"),
    [
        (None, "traces.json is missing"),
        ({}, "traces.json holds no trajectory"),  # an evaluation without a K = 7 cell
    ],
)
def test_figures_without_trajectories_say_that_fig3_and_fig4_were_skipped(tmp_path, traces, said):
    folder = results(tmp_path / "eval", GRID, traces)
    skipped = []
    names = [p.name for p in figures.figures_from_results(folder, tmp_path / "png", skipped)]
    assert names == ["fig2a_jain_vs_k.png", "fig2b_aoi_vs_k.png", "energy_per_policy.png"]
    assert len(skipped) == 1
    assert "Fig. 3" in skipped[0] and "Fig. 4" in skipped[0] and said in skipped[0]


def test_figures_without_one_auv_skip_fig4_only(tmp_path):
    folder = results(tmp_path / "eval", GRID, {"ppo, N=2": trace(2)})
    skipped = []
    names = [p.name for p in figures.figures_from_results(folder, tmp_path / "png", skipped)]
    assert "fig3_trajectories_k3.png" in names and "fig4_speed_heading_n1.png" not in names
    assert skipped == [
        "skipped Fig. 4 (speed and heading, N = 1): no trajectory with N = 1 in "
        f"{folder / 'traces.json'} (evaluate with --n-auvs 1)"
    ]


def test_file_names_and_titles_carry_the_noise_model(tmp_path):
    rows = [r | {"noise_model": "wenz", "max_current_mps": 0.0} for r in GRID]
    folder = results(tmp_path / "eval", rows, {"ppo, N=1": trace(1)})
    skipped = []
    names = {p.name for p in figures.figures_from_results(folder, tmp_path / "png", skipped)}
    assert {"fig2a_jain_vs_k_wenz.png", "fig2b_aoi_vs_k_wenz.png"} <= names and not skipped
    assert figures.condition(rows) == (
        "Wenz noise, no current, MuJoCo backend, random layouts, 3 episodes per cell"
    )
    current = [r | {"noise_model": "flat", "max_current_mps": 0.71} for r in GRID]
    assert figures.condition_suffix(current) == "_flat_current"
    assert figures.condition(GRID).startswith("noise model not recorded")


def test_confidence_intervals_use_student_t_and_stay_in_range():
    # 3 episodes, population std 0.05: s / sqrt(n) = 0.05 / sqrt(2); t(2) = 4.303
    half = 4.303 * 0.05 / math.sqrt(2)
    assert figures.ci95(0.5, 0.05, 3, 0.0, 1.0) == pytest.approx((half, half))
    low, high = figures.ci95(0.98, 0.05, 3, 0.0, 1.0)  # Jain cannot exceed 1
    assert low == pytest.approx(half) and high == pytest.approx(0.02)
    assert figures.ci95(5.0, 1.0, 1, 0.0, math.inf) == (0.0, 0.0)  # one episode: no interval
    assert figures.ci95(5.0, 1.0, 101, 0.0, math.inf)[0] == pytest.approx(0.1984, abs=1e-3)


def test_folders_read_together_gather_one_policy_per_n_under_one_label(tmp_path):
    """The learned policy of each N evaluated apart (its own folder) is one series."""
    one = results(tmp_path / "n1", [row(p, 1, k) for p in ("greedy", "a/best") for k in (3, 11)])
    two = [row(p, 2, k, training_seeds=5) for p in ("greedy", "b/best") for k in (3, 11)]
    folders = [one, results(tmp_path / "n2", two, {"b/best, N=2": trace(2)})]
    labels = {"a/best": "ppo-general", "b/best": "ppo-general"}
    rows, traces = figures.read_results(folders, labels, ["a/best", "b/best"])
    assert {(r["policy"], r["n_auvs"]) for r in rows} == {("ppo-general", 1), ("ppo-general", 2)}
    assert list(traces) == ["ppo-general, N=2"]
    assert figures.condition(rows).endswith("3 episodes per cell (5 training seeds)")
    with pytest.raises(UsageError, match=r"no policy 'c/best' in the results: accepted \["):
        figures.read_results(folders, {"c/best": "x"}, None)
    with pytest.raises(UsageError, match="'greedy' at N=1, K=3 twice"):
        figures.read_results([one, one], {}, None)
    with pytest.raises(UsageError, match="'same' at N=1, K=3 twice"):  # a label that merges a cell
        figures.read_results([one], {"greedy": "same", "a/best": "same"}, None)


def test_a_long_policy_name_widens_fig2_instead_of_being_cut(tmp_path):
    """The legends right of the axes lie inside the image, whatever the names' length."""

    def width_px(name):
        rows = [r | {"policy": name} if r["policy"] == "ppo" else r for r in GRID]
        path = figures.vs_k_figure(rows, "mean_aoi", "AoI", "t", math.inf, tmp_path / f"{name}.png")
        return struct.unpack(">I", path.read_bytes()[16:20])[0]  # the PNG header's width

    assert width_px("ppo-general-n2-aoi-2m+rollout+dock") > width_px("ppo") + 100
