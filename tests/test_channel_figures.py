"""Figures say which acoustic channel they show: `ChannelConfig.label` in result rows, the
title's channel line and the file names' suffix."""

import json

from conftest import ROOT
from test_figures import GRID

from iout_mj.config import ChannelConfig
from iout_mj.experiments import figures
from iout_mj.experiments.evaluate import evaluate
from iout_mj.scenarios import load_config

REALISTIC = "depth+propagation+packets+interference+fading"


def test_the_channel_label_names_its_features_and_a_non_thorp_absorption():
    assert ChannelConfig().label == "paper"
    shipped = load_config(ROOT / "training/configs/env/realistic-channel.yaml")
    assert shipped.channel.label == REALISTIC
    fg = ChannelConfig(features=("depth",), absorption="francois-garrison")
    assert fg.label == "depth+francois-garrison"
    assert ChannelConfig(absorption="francois-garrison").label == "francois-garrison"


def test_figures_of_a_channel_say_it_in_the_title_and_the_file_names(tmp_path):
    rows = [r | {"noise_model": "flat", "max_current_mps": 0.0, "channel": REALISTIC} for r in GRID]
    folder = tmp_path / "eval"
    folder.mkdir()
    (folder / "results.json").write_text(json.dumps(rows))
    names = [p.name for p in figures.figures_from_results(folder, tmp_path / "png", [])]
    assert names == [
        "fig2a_jain_vs_k_flat_channel.png",
        "fig2b_aoi_vs_k_flat_channel.png",
        "energy_per_policy_flat_channel.png",
    ]
    assert figures.condition(rows) == (
        "flat noise, no current, MuJoCo backend, random layouts, 3 episodes per cell;\n"
        "channel: depth, propagation, packets, interference, fading"
    )


def test_the_papers_channel_keeps_the_file_names_and_says_so():
    rows = [r | {"noise_model": "wenz", "channel": "paper"} for r in GRID]
    assert figures.condition_suffix(rows) == "_wenz"
    assert figures.condition(rows).endswith(";\nthe paper's channel")
    mixed = rows + [r | {"n_nodes": 5, "channel": "packets"} for r in rows[:1]]
    assert figures.condition_suffix(mixed) == "_wenz_channel"
    assert figures.condition(mixed).endswith("channel: packets / the paper's channel")
    assert figures.condition_suffix(GRID) == "" and "channel" not in figures.condition(GRID)


def test_evaluate_records_each_cell_s_channel_so_figures_can_name_it():
    realistic = ROOT / "training/configs/env/realistic-channel.yaml"
    for base, label in ((None, "paper"), (realistic, REALISTIC)):
        eps, rows = evaluate(["greedy"], [2], [5], 1, 0, "kinematic", 1, False, base=base)
        assert {r["channel"] for r in (*eps, *rows)} == {label}
