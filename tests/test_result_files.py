"""`compare`, `figures` and `bench --from-json` on malformed files: one ResultFileError naming
the file and what is wrong (on the command line: exit 2, no traceback)."""

import json
import os

import pytest
from conftest import ROOT

from iout_mj.errors import ResultFileError, UsageError
from iout_mj.experiments import bench_report, compare, figures
from iout_mj.mission.stats import SUMMARY_KEYS

BENCH = ROOT / "benchmarks" / "results-2cpu.json"


def row(policy, n_nodes, **changes):
    r = {"policy": policy, "n_auvs": 1, "n_nodes": n_nodes, "layout": "paper"}
    r |= {"backend": "kinematic", "episodes": 2}
    for i, key in enumerate(SUMMARY_KEYS):
        r[key], r[key + "_std"] = 10.0 + i, 0.5
    return r | changes


def trace(**changes):
    t = {
        "positions_m": [[[50.0, 50.0]], [[60.0, 50.0]]],
        "headings_rad": [[0.0], [0.1]],
        "speeds_mps": [[1.0], [1.5]],
        "nodes_m": [[100.0, 100.0], [800.0, 500.0]],
        "delivered_bits_per_node": [12000.0, 0.0],
        "dock_center_m": [830.0, 830.0],
        "dock_radius_m": 70.0,
        "area_m": [1000.0, 1000.0],
        "slot_s": 25.0,
    }
    return t | changes


@pytest.fixture
def results(tmp_path):
    folder = tmp_path / "eval"
    folder.mkdir()
    rows = [row("ppo", 7), row("greedy", 7, mean_aoi_horizon=20.0)]
    (folder / "results.json").write_text(json.dumps(rows))
    episodes = [
        {k: r[k] for k in ("policy", "n_auvs", "n_nodes", "layout", "backend")}
        | {"seed": seed, "training_seed": 0 if r["policy"] == "ppo" else None}
        | {"mean_aoi_horizon": r["mean_aoi_horizon"] + (seed - 0.5) * 2 * r["mean_aoi_horizon_std"]}
        for r in rows
        for seed in (0, 1)
    ]
    (folder / "episodes.json").write_text(json.dumps(episodes))
    (folder / "traces.json").write_text(json.dumps({"ppo, N=1": trace()}))
    return folder


def test_well_formed_files_give_the_table_and_figures(results, tmp_path):
    rows, episodes = compare.read_rows(results), compare.read_episodes(results)
    (table,) = compare.compare(rows, episodes, "ppo", "greedy", reps=200)["cells"]
    assert table["ratio"] == pytest.approx(11.0 / 20.0)  # IQMs of 10.5, 11.5 and 19.5, 20.5
    names = [p.name for p in figures.figures_from_results(results, tmp_path / "png")]
    assert "fig3_trajectories_k2.png" in names and "fig4_speed_heading_n1.png" in names
    assert "| kinematic_steps_per_s N2_K13" in bench_report.format_markdown(
        bench_report.read_result(BENCH)
    )


def _rows(folder, rows):
    (folder / "results.json").write_text(rows if isinstance(rows, str) else json.dumps(rows))


@pytest.mark.parametrize(
    ("rows", "match"),
    [
        ("[{", "results.json is not valid JSON"),
        ("[" * 100_000, "results.json is nested too deeply"),
        (b"\xff\xfe", "results.json is not UTF-8"),
        ({"ppo": 1}, "results.json is .*: accepted a JSON list of at least 1"),
        ([], "accepted a JSON list of at least 1 entries"),
        ([7], "row 0 is 7: accepted a JSON object"),
        ([row("ppo", 7, mean_aoi_horizon=float("nan"))], "row 0: mean_aoi_horizon is nan"),
        ([row("ppo", 7, docking_rate="all")], "row 0: docking_rate is 'all': accepted a finite"),
        ([row("ppo", 7, delivered_bits_std=-1.0)], "delivered_bits_std is -1.0: .* >= 0"),
        ([{"policy": "ppo"}], "row 0 has no 'layout'"),
        ([row("ppo", True)], "row 0: n_nodes is True: accepted an integer >= 1"),
        ([row("ppo", 7), row("ppo", 7)], r"row 1 repeats the cell \('ppo', 'paper'"),
        ([row("ppo", 7), row("greedy", 7, mean_aoi_horizon=0.0)], "row 1: mean_aoi_horizon is 0"),
    ],
)
def test_compare_refuses_a_malformed_results_file(results, rows, match):
    if isinstance(rows, bytes):
        (results / "results.json").write_bytes(rows)
    else:
        _rows(results, rows)
    with pytest.raises(ResultFileError, match=match) as info:
        compare.read_rows(results)
    assert str(results / "results.json") in str(info.value)


def test_compare_refuses_links_fifos_and_missing_files(results, tmp_path):
    (results / "results.json").unlink()
    with pytest.raises(ResultFileError, match=r"results.json does not exist: accepted a folder"):
        compare.read_rows(results)
    (results / "results.json").symlink_to("/proc/self/environ")
    with pytest.raises(ResultFileError, match=r"results.json is a symbolic link"):
        compare.read_rows(results)
    (results / "results.json").unlink()
    os.mkfifo(results / "results.json")
    with pytest.raises(ResultFileError, match=r"results.json is a FIFO"):
        compare.read_rows(results)


def test_compare_without_a_common_cell_is_a_usage_error(results):
    rows, episodes = compare.read_rows(results), compare.read_episodes(results)
    with pytest.raises(UsageError, match="no cell holds both 'ppo' and 'planner'"):
        compare.compare(rows, episodes, "ppo", "planner")


@pytest.mark.parametrize(
    ("change", "match"),
    [
        (lambda e: e.pop("seed"), "episode 0 has no 'seed'"),
        (lambda e: e.update(training_seed="a"), "episode 0: training_seed is 'a'"),
        (lambda e: e.update(mean_aoi_horizon=None), "episode 0: mean_aoi_horizon is None"),
        (lambda e: e.update(mean_aoi_horizon=-1.0), "episode 0: mean_aoi_horizon is -1.0"),
    ],
)
def test_compare_refuses_a_malformed_episodes_file(results, change, match):
    path = results / "episodes.json"
    episodes = json.loads(path.read_text())
    change(episodes[0])
    path.write_text(json.dumps(episodes))
    with pytest.raises(ResultFileError, match=match) as info:
        compare.read_episodes(results)
    assert str(path) in str(info.value)


@pytest.mark.parametrize(
    ("traces", "match"),
    [
        ([1], "traces.json is .*: accepted a JSON object"),
        ({"a": 1}, "trace 'a' is 1: accepted a JSON object"),
        ({"a": trace(positions_m=[[[1, 2]], [[1]]])}, "positions_m is not a numeric array"),
        ({"a": trace(positions_m=[[[1, 2, 3]]])}, r"positions_m has shape \(1, 1, 3\)"),
        ({"a": trace(positions_m=[])}, r"positions_m has shape \(0,\)"),
        ({"a": trace(speeds_mps=[[1.0]])}, r"speeds_mps has shape \(1, 1\): .* of shape 2 x 1"),
        ({"a": trace(delivered_bits_per_node=[1.0])}, "delivered_bits_per_node has shape"),
        ({"a": trace(dock_radius_m=None)}, "dock_radius_m is None"),
        ({"a": trace(area_m=[0, 1000])}, "area_m must be two sizes > 0"),
        ({"a": trace(nodes_m="paper")}, r"nodes_m is not a numeric array|nodes_m has shape"),
    ],
)
def test_figures_refuse_malformed_traces_before_drawing(results, tmp_path, traces, match):
    (results / "traces.json").write_text(json.dumps(traces))
    with pytest.raises(ResultFileError, match=match):
        figures.figures_from_results(results, tmp_path / "png")
    assert not (tmp_path / "png").exists()  # nothing drawn from a half-read folder


def test_figures_refuse_malformed_results(results, tmp_path):
    _rows(results, [row("ppo", 7, jain_std=float("inf"))])
    with pytest.raises(ResultFileError, match="row 0: jain_std is inf"):
        figures.figures_from_results(results, tmp_path / "png")


@pytest.mark.parametrize(
    ("state", "match"),
    [
        ("{", "state.json is not valid JSON"),
        ({"phase": 1}, "history is None: accepted a JSON list"),
        ({"history": [{"num_timesteps": 64}]}, r"history\[0\] has no 'backend'"),
        (
            {"history": [{"num_timesteps": 64, "backend": "kinematic", "jain": 1.0}]},
            r"history\[0\] has no 'mean_aoi_horizon'",
        ),
        (
            {
                "history": [
                    {"num_timesteps": -1, "backend": "kinematic", "jain": 1, "docking_rate": 0}
                ]
            },
            r"num_timesteps is -1: accepted an integer >= 0",
        ),
    ],
)
def test_training_curves_refuse_a_malformed_state(tmp_path, state, match):
    run = tmp_path / "run"
    run.mkdir()
    (run / "state.json").write_text(state if isinstance(state, str) else json.dumps(state))
    with pytest.raises(ResultFileError, match=match):
        figures.training_curves([run], tmp_path / "curves.png")


def test_training_curves_pool_the_seeds_of_a_recipe(tmp_path):
    def run(folder, name, aoi, backends=("kinematic", "kinematic", "mujoco")):
        path = tmp_path / folder
        path.mkdir()
        if name is not None:
            (path / "config.yaml").write_text(f"name: {name}\n")
        history = [
            {
                "num_timesteps": 100 * i,
                "backend": b,
                "mean_aoi_horizon": a,
                "jain": 0.9,
                "docking_rate": 1.0,
            }
            for i, (a, b) in enumerate(zip(aoi, backends, strict=False))
        ]
        (path / "state.json").write_text(json.dumps({"history": history}))
        return path

    runs = [
        run("a", "fast", [9, 8, 7]),
        run("b", "fast", [11, 10]),  # a seed that reached two evaluations
        run("slow-seed3", None, [12, 12, 12]),  # no config: the folder names the recipe
    ]
    curves = figures.recipe_curves(runs)
    assert set(curves) == {"fast", "slow"} and curves["fast"]["runs"] == 2
    assert curves["fast"]["steps"].tolist() == [0, 100]
    assert curves["fast"]["mean_aoi_horizon"].mean(axis=0).tolist() == [10, 9]
    assert curves["fast"]["mujoco_from"] is None and curves["slow"]["mujoco_from"] == 100
    assert figures.training_curves(runs, tmp_path / "c.png").stat().st_size > 10_000


def _bench(tmp_path, change):
    result = json.loads(BENCH.read_text())
    change(result)
    path = tmp_path / "bench.json"
    path.write_text(json.dumps(result))
    return path


@pytest.mark.parametrize(
    ("change", "match"),
    [
        (lambda r: r.pop("memory"), "memory is None: accepted a JSON object"),
        (lambda r: r["memory"].pop("training_envs"), "memory has no 'training_envs'"),
        (lambda r: r.update(render_fps=float("nan")), "render_fps is nan"),
        (lambda r: r["slot_vs_raw"]["N1_K7"].update(ratio="fast"), r"slot_vs_raw.N1_K7: ratio"),
        (lambda r: r.update(physics_batch=4), "slot_vs_raw.N1_K7 has no 'batch_4_env_steps"),
        (
            lambda r: r["kinematic_single_env_steps_per_s"].pop("N4_K13"),
            "kinematic_single_env_steps_per_s has no 'N4_K13'",
        ),
        (lambda r: r["machine"].update(cpus=0), "machine: cpus is 0: accepted an integer >= 1"),
        (lambda r: r.update(ppo_fps=[1, 2, 3]), r"ppo_fps is \[1, 2, 3\]: accepted a JSON object"),
    ],
)
def test_bench_refuses_a_malformed_saved_run(tmp_path, change, match):
    path = _bench(tmp_path, change)
    with pytest.raises(ResultFileError, match=match) as info:
        bench_report.read_result(path)
    assert str(path) in str(info.value)
    with pytest.raises(ResultFileError, match=match):
        bench_report.format_table(json.loads(path.read_text()))


def test_bench_refuses_a_file_that_is_not_json(tmp_path):
    path = tmp_path / "bench.json"
    path.write_text('{"machine": ')
    with pytest.raises(ResultFileError, match=r"bench.json is not valid JSON"):
        bench_report.read_result(path)


def test_the_command_line_reports_malformed_files_without_a_traceback(results, tmp_path, cli):
    _rows(results, [row("ppo", 7, mean_aoi_horizon="x", jain="x")])
    bench = _bench(tmp_path, lambda r: r.pop("memory"))
    for args, text in (
        (("compare", "--results", results, "--policy", "ppo"), "mean_aoi_horizon is 'x'"),
        (("figures", "--results", results), "jain is 'x'"),
        (("bench", "--from-json", bench), "memory is None"),
    ):
        out = cli(*args, check=False)
        assert out.returncode == 2 and text in out.stderr, out.stderr
        assert "Traceback" not in out.stderr
