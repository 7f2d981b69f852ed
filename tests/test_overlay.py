"""The video's 2-D layer and palette, without rendering: the layout keeps the text panel off
the map and legible, AUV colours are told apart from each other and from everything else."""

import itertools

import mujoco
import numpy as np
import pytest

from iout_mj import palette
from iout_mj.backends.mujoco import overlay, vehicle
from iout_mj.scenarios import make_config


@pytest.mark.parametrize(("width", "height"), [(960, 540), (1280, 720), (640, 480), (200, 120)])
def test_the_panel_lies_beside_the_map_never_over_it(width, height):
    lay = overlay.frame_layout(width, height)
    assert lay.side_w >= overlay.MIN_SIDE_PX and lay.map_w == lay.map_h  # a square map
    assert lay.map_top + lay.map_h <= height
    assert 0 < lay.chase_h < height and lay.panel_h == height - lay.chase_h
    assert lay.map_w + lay.side_w == width  # the column starts where the map ends


def test_a_frame_too_narrow_for_a_column_is_the_map_alone():
    lay = overlay.frame_layout(96, 64)
    assert (lay.map_w, lay.map_h, lay.side_w, lay.panel_h) == (96, 64, 0, 0)


@pytest.mark.parametrize("n_auvs", [1, 2, 3, 4])
def test_panel_text_is_at_least_16_px_at_960x540(n_auvs):
    lay = overlay.frame_layout(960, 540)
    sample = overlay.worst_case(55, 25.0, n_auvs, 50.0)
    panel = overlay.Panel(lay.side_w, lay.panel_h, sample)
    assert panel.size >= 16
    image = panel.image(sample)
    assert image.shape == (lay.panel_h, lay.side_w, 3)
    # the last row of text (the link legend) ends above the panel's bottom edge
    assert np.all(image[-2:] == overlay.PANEL_RGB)


def test_panel_says_which_aoi_is_current_and_which_a_time_average():
    state = overlay.worst_case(55, 25.0, 2, 50.0)
    state = overlay.PanelState(
        **(vars(state) | {"aoi_now": 7.6, "aoi_so_far": 5.92, "docked_at": (49, None)})
    )
    state = overlay.PanelState(**(vars(state) | {"docked": (True, False), "chased": 1}))
    lines = overlay.Panel(420, 304, state).lines(state)
    assert "AoI now: 7.6 slots (node mean)" in lines
    assert "mean AoI so far: 5.9 (over time)" in lines
    assert any(line.endswith("docked at slot 49") for line in lines)
    assert any(line.startswith("AUV 2") and line.endswith("under way") for line in lines)
    assert lines[0].endswith("chase view: AUV 2")


def _distance(a, b):
    return float(np.linalg.norm(np.asarray(a)[:3] - np.asarray(b)[:3]))


def test_four_auv_colours_are_distinct_and_none_is_a_node_dock_or_link_colour():
    auvs = palette.AUV_RGBA[:4]
    for a, b in itertools.combinations(auvs, 2):
        assert _distance(a, b) > 0.5
    model = vehicle.build_model(make_config(1, 7))
    dock = model.mat_rgba[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_MATERIAL, "dock")]
    ramp = palette.aoi_rgba(np.linspace(0, 1, 101))  # every node colour
    taken = [dock, palette.NODE_RGB, palette.AET_RGBA, palette.UPLINK_RGBA, palette.FAILED_RGBA]
    for auv in auvs:
        assert min(_distance(auv, c) for c in [*taken, *ramp]) > 0.35


def test_projection_puts_the_area_corners_where_the_top_camera_sees_them():
    # a camera 1000 m above (500, 500) with a 90 degree field of view sees 2000 m across
    px = overlay.project(
        np.array([[500.0, 500.0, 0.0], [1500.0, 500.0, 0.0], [500.0, 1500.0, 0.0]]),
        np.array([500.0, 500.0, 1000.0]),
        np.eye(3),
        90.0,
        400,
        400,
    )
    np.testing.assert_allclose(px, [[200, 200], [400, 200], [200, 0]], atol=1e-9)


@pytest.mark.parametrize(("span", "bar"), [(200.0, 200.0), (190.0, 100.0), (600.0, 500.0)])
def test_scale_bar_lengths_are_round(span, bar):
    assert overlay.nice_length_m(span) == bar
