"""validate-energy tests the speeds the config can reach: its grid comes from V_max."""

import dataclasses
import itertools

import pytest

from iout_mj.experiments.energy_validation import maneuvers, steady_state
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
