"""Property tests of the config bounds: any accepted config steps with finite rewards and
observations inside the declared space; any value just outside a range is refused by name."""

import math

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import iout_mj  # noqa: F401  (registers the env)
from iout_mj.config import Config
from iout_mj.envs import ENV_ID
from iout_mj.schema import ConfigError

PROPERTY = settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])

# The accepted ranges, written out here as the specification (section, field, low, high);
# `OPEN_LOW` fields exclude their low end.
RANGES = [
    ("motion", "v_max_mps", 0.5, 20.0),
    ("motion", "drag_coefficient", 1e-3, 0.1),
    ("motion", "wetted_area_m2", 0.5, 30.0),
    ("motion", "water_density_kgpm3", 900.0, 1100.0),
    ("motion", "prop_efficiency", 0.05, 1.0),
    ("motion", "hotel_power_w", 0.0, 1e5),
    ("motion", "dtheta_max_deg", 0.0, 180.0),
    ("motion", "dv_max_mps", 0.0, 20.0),
    ("motion", "battery_j", 0.0, 1e12),
    ("motion", "heading_levels", 3, 101),
    ("motion", "speed_levels", 3, 101),
    ("acoustics", "f_wet_khz", 0.1, 200.0),
    ("acoustics", "f_data_khz", 0.1, 200.0),
    ("acoustics", "p_tx_w", 1e-3, 1e6),
    ("acoustics", "eta_tx", 0.01, 1.0),
    ("acoustics", "eta_harv", 0.01, 1.0),
    ("acoustics", "di_tx_db", 0.0, 40.0),
    ("acoustics", "di_rx_db", 0.0, 40.0),
    ("acoustics", "spreading_factor", 1.0, 2.0),
    ("acoustics", "rvs_db", -250.0, -100.0),
    ("acoustics", "load_resistance_ohm", 0.1, 1e6),
    ("acoustics", "n_hydrophones", 1, 1000),
    ("acoustics", "bandwidth_hz", 1.0, 1e6),
    ("acoustics", "noise_level_db", 0.0, 150.0),
    ("acoustics", "shipping_activity", 0.0, 1.0),
    ("acoustics", "wind_speed_mps", 0.0, 100.0),
    ("network", "k_reset", 1, 10_000),
    ("network", "aoi_max", 1.0, 1e6),
    ("network", "node_initial_energy_j", 0.0, 1e9),
    ("reward", "fairness_min_deliveries", 0, 1_000_000),
    ("reward", "stall_distance_m", 0.0, 20_000.0),
    ("reward", "margin_epsilon_j", 1e-12, 1e6),
    ("reward", "collision_sigma_m", 0.1, 20_000.0),
    ("reward", "safety_distance_m", 0.0, 20_000.0),
    ("reward", "deadline_speed_mps", 0.0, 20.0),
    ("reward", "fairness_lambda", 0.0, 1e6),
    ("physics", "timestep_s", 1e-3, 0.25),
    ("physics", "current_jitter_mps", 0.0, 20.0 / math.sqrt(2)),
    ("scenario", "start_heading_rad", -2 * math.pi, 2 * math.pi),
    ("scenario", "slot_s", 0.1, 2500.0),
    ("scenario", "horizon_slots", 1, 10_000),
    ("scenario", "start_jitter_m", 0.0, 20_000.0),
    ("scenario", "start_heading_jitter_deg", 0.0, 180.0),
    *(("weights", name, -1e6, 1e6) for name in ("aoi", "collision", "dock_all", "deadline")),
]
OPEN_LOW = {"dtheta_max_deg", "dv_max_mps", "battery_j"}
SPEC = {name: (section, low, high) for section, name, low, high in RANGES}


def between(low: float, high: float, open_low: bool = False) -> st.SearchStrategy[float]:
    """Anywhere in [low, high], with both ends (or just above an open low end) drawn often."""
    lo = math.nextafter(low, math.inf) if open_low else low
    return st.one_of(st.sampled_from([lo, high]), st.floats(lo, high))


def field(name: str) -> st.SearchStrategy[float]:
    _, low, high = SPEC[name]
    if isinstance(low, int):
        return st.one_of(st.sampled_from([low, high]), st.integers(low, high))
    return between(low, high, name in OPEN_LOW)


def odd_levels() -> st.SearchStrategy[int]:
    return st.one_of(st.sampled_from([3, 101]), st.integers(1, 50).map(lambda i: 2 * i + 1))


def point(ax: float, ay: float, margin: float) -> st.SearchStrategy[list[float]]:
    f = between(margin, 1 - margin)
    return st.tuples(f, f).map(lambda p: [p[0] * ax, p[1] * ay])


@st.composite
def configs(draw: st.DrawFn) -> dict:
    """An accepted config as a dict, every value drawn over its whole range."""
    rho, area_s = draw(field("water_density_kgpm3")), draw(field("wetted_area_m2"))
    v_max = draw(field("v_max_mps"))
    # The current: anything the vehicle can out-run (|current| + sqrt(2) jitter <= V_max).
    jitter = draw(between(0.0, 1.0)) * draw(st.sampled_from([0.0, 1.0])) * v_max / math.sqrt(2)
    jitter *= 1 - 1e-9
    speed = (v_max - math.sqrt(2) * jitter) * draw(between(0.0, 1.0)) * (1 - 1e-9)
    angle = draw(between(-math.pi, math.pi))
    flow = v_max + speed + math.sqrt(2) * jitter
    # Drag and timestep inside MuJoCo's stable region (drag factor >= 4.5 N s^2/m^2, drag x
    # flow x dt <= 10 kg, flow x dt <= 1.25 m) and a slot of at most 10,000 timesteps.
    per_cd = 0.5 * rho * area_s  # drag factor per unit C_d
    c_low, c_high = max(4.5, per_cd * 1e-3), min(per_cd * 0.1, 10.0 / (flow * 1.1e-3))
    cd = draw(between(c_low * (1 + 1e-9), c_high * (1 - 1e-9))) / per_cd
    dt_max = min(0.25, 1.25 / flow, 10.0 / (per_cd * cd * flow)) * (1 - 1e-9)
    slot = draw(between(0.1, min(2500.0, 10_000 * dt_max) * (1 - 1e-9)))
    n_low, n_high = math.ceil(slot / dt_max), min(10_000, math.floor(slot / 1e-3 * (1 - 1e-12)))
    substeps = draw(st.one_of(st.sampled_from([n_low, n_high]), st.integers(n_low, n_high)))
    ax, ay = (draw(between(10.0, 20_000.0)) for _ in range(2))
    radius = draw(between(1e-3, min(ax, ay) / 2))
    n_auvs, n_nodes = draw(st.integers(1, 4)), draw(st.integers(2, 30))
    bandwidth = draw(field("bandwidth_hz"))
    acoustics = {name: draw(field(name)) for name, (s, *_) in SPEC.items() if s == "acoustics"}
    acoustics |= {
        "bandwidth_hz": bandwidth,
        "data_rate_bps": draw(between(1.0, 64 * bandwidth)),
        "charging_s": draw(between(0.0, slot, open_low=True)),
        "data_s": draw(between(0.0, slot, open_low=True)),
        "noise_model": draw(st.sampled_from(["flat", "wenz"])),
    }
    motion = {name: draw(field(name)) for name, (s, *_) in SPEC.items() if s == "motion"}
    motion |= {
        "v_max_mps": v_max,
        "water_density_kgpm3": rho,
        "wetted_area_m2": area_s,
        "drag_coefficient": cd,
        "heading_levels": draw(odd_levels()),
        "speed_levels": draw(odd_levels()),
        "initial_speed_mps": draw(between(0.0, v_max)),
    }
    reward = {name: draw(field(name)) for name, (s, *_) in SPEC.items() if s == "reward"}
    reward["weights"] = {n: draw(field(n)) for n, (s, *_) in SPEC.items() if s == "weights"}
    network = {name: draw(field(name)) for name, (s, *_) in SPEC.items() if s == "network"}
    scenario = {
        name: draw(field(name))
        for name in ("start_heading_rad", "start_jitter_m", "start_heading_jitter_deg")
    }
    scenario |= {
        "area_m": [ax, ay],
        "n_auvs": n_auvs,
        "nodes_m": [draw(point(ax, ay, 0.0)) for _ in range(n_nodes)],
        "starts_m": [draw(point(ax, ay, 1e-6)) for _ in range(n_auvs)],
        "dock_radius_m": radius,
        "dock_center_m": [
            radius + draw(between(0.0, 1 - 1e-12)) * (side - 2 * radius) for side in (ax, ay)
        ],
        "slot_s": slot,
        "horizon_slots": draw(st.sampled_from([1, 2, 55, 10_000])),
    }
    physics = {
        "timestep_s": slot / substeps,
        "current_mps": [speed * math.cos(angle), speed * math.sin(angle)],
        "current_jitter_mps": jitter,
    }
    return {
        "scenario": scenario,
        "motion": motion,
        "acoustics": acoustics,
        "network": network,
        "reward": reward,
        "physics": physics,
    }


def fly(data: dict, backend: str, slots: int, seed: int) -> None:
    """A few slots of random actions: every reward, term and observation finite and inside
    the declared observation space."""
    env = gym.make(ENV_ID, backend=backend, config=Config.from_dict(data))
    obs, _ = env.reset(seed=seed)
    env.action_space.seed(seed)
    assert env.observation_space.contains(obs), obs
    for _ in range(slots):
        obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
        assert "error" not in info, info.get("error")
        assert np.isfinite(reward) and np.isfinite(list(info["reward_terms"].values())).all()
        assert np.isfinite(obs).all() and env.observation_space.contains(obs), obs
        if terminated or truncated:
            break
    env.close()


@PROPERTY
@given(data=configs(), seed=st.integers(0, 2**16))
def test_any_accepted_config_steps_finite_and_inside_the_observation_space(data, seed):
    fly(data, "kinematic", slots=4, seed=seed)


def outside(name: str) -> list[float]:
    """Values just below and just above the accepted range of `name`."""
    _, low, high = SPEC[name]
    if isinstance(low, int):
        return [low - 1, high + 1]
    below = low if name in OPEN_LOW else math.nextafter(low, -math.inf)
    return [below, math.nextafter(high, math.inf)]


def place(name: str, value: float) -> dict:
    section, *_ = SPEC[name]
    if section == "weights":
        return {"reward": {"weights": {name: value}}}
    return {section: {name: value}}


COMPANIONS = {
    # An end of a range that other fields' defaults do not admit: what else it needs.
    ("v_max_mps", 0.5): {"motion": {"initial_speed_mps": 0.0}},
    ("drag_coefficient", 1e-3): {"motion": {"wetted_area_m2": 30.0}},
    ("drag_coefficient", 0.1): {"physics": {"timestep_s": 0.0125}},
    ("wetted_area_m2", 0.5): {"motion": {"drag_coefficient": 0.02}},
    ("wetted_area_m2", 30.0): {"physics": {"timestep_s": 0.025}},
    ("timestep_s", 1e-3): {
        "scenario": {"slot_s": 10.0},
        "acoustics": {"charging_s": 10.0, "data_s": 10.0},
    },
    ("bandwidth_hz", 1.0): {"acoustics": {"data_rate_bps": 64.0}},
    ("slot_s", 0.1): {
        "physics": {"timestep_s": 0.1},
        "acoustics": {"charging_s": 0.1, "data_s": 0.1},
    },
    ("slot_s", 2500.0): {"physics": {"timestep_s": 0.25}},
    ("current_jitter_mps", 20.0 / math.sqrt(2)): {
        "motion": {"v_max_mps": 20.0},
        "physics": {"timestep_s": 0.025},
    },
}


def merged(data: dict, extra: dict) -> dict:
    for section, values in extra.items():
        data[section] = {**data.get(section, {}), **values}
    return data


@pytest.mark.parametrize("name", sorted(SPEC))
def test_the_ends_of_each_range_are_accepted_and_just_outside_refused_by_name(name):
    _, low, high = SPEC[name]
    for value in (low, high):
        if name in OPEN_LOW and value == low:
            continue
        if name in ("heading_levels", "speed_levels"):
            value += 0 if value % 2 else 1
        Config.from_dict(merged(place(name, value), COMPANIONS.get((name, value), {})))
    for value in outside(name):
        with pytest.raises(ConfigError, match=rf"{name}={value!r}|{name}={float(value)!r}"):
            Config.from_dict(place(name, value))


@PROPERTY
@given(name=st.sampled_from(sorted(SPEC)), data=st.data())
def test_any_value_outside_a_range_is_refused_naming_the_field(name, data):
    _, low, high = SPEC[name]
    below = low if name in OPEN_LOW else math.nextafter(low, -math.inf)
    value = data.draw(
        st.floats(max_value=below) | st.floats(min_value=math.nextafter(high, math.inf))
    )
    with pytest.raises(ConfigError, match=name) as err:
        Config.from_dict(place(name, value))
    assert "accepted" in str(err.value)


@pytest.mark.parametrize(
    ("data", "field_name", "accepted"),
    [
        (
            {"motion": {"v_max_mps": 1}, "physics": {"current_mps": [3, 0]}},
            "current_mps",
            "out-run",
        ),
        ({"physics": {"current_mps": [3, 0], "current_jitter_mps": 0.8}}, "current_mps", "out-run"),
        ({"physics": {"timestep_s": 0.03}}, "timestep_s", "divisor of scenario.slot_s=25"),
        ({"physics": {"timestep_s": 1e-3}}, "timestep_s", "at most 10000 substeps"),
        ({"motion": {"v_max_mps": 20}, "physics": {"timestep_s": 0.25}}, "timestep_s", "1.25 m"),
        (
            {"motion": {"drag_coefficient": 0.1}, "physics": {"timestep_s": 0.25}},
            "timestep_s",
            "kg",
        ),
        ({"motion": {"drag_coefficient": 0.002}}, "drag_coefficient", "4.5 N s^2/m^2"),
        ({"acoustics": {"data_rate_bps": 2e6}}, "data_rate_bps", "64 bit/s per Hz"),
        ({"acoustics": {"charging_s": 26.0}}, "charging_s", "one slot"),
        ({"acoustics": {"data_s": 26.0}}, "data_s", "one slot"),
        ({"motion": {"initial_speed_mps": 4.5}}, "initial_speed_mps", "up to v_max_mps"),
        ({"motion": {"heading_levels": 12}}, "heading_levels", "odd integer"),
        ({"network": {"k_reset": 2**63}}, "k_reset", "integer in"),
        ({"scenario": {"horizon_slots": 10**400}}, "horizon_slots", "integer in"),
        ({"motion": {"battery_j": 10**400}}, "battery_j", "finite"),
    ],
)
def test_joint_bounds_name_the_field_and_what_is_accepted(data, field_name, accepted):
    with pytest.raises(ConfigError, match=field_name) as err:
        Config.from_dict(data)
    assert accepted in str(err.value)


def corner(
    v_max: float, cd: float, current: list[float], dt: float, slot: float, **motion: float
) -> dict:
    return {
        "motion": {
            "v_max_mps": v_max,
            "initial_speed_mps": v_max,
            "dv_max_mps": v_max,
            "dtheta_max_deg": 180.0,
            "drag_coefficient": cd,
            **motion,
        },
        "physics": {"timestep_s": dt, "current_mps": current},
        "scenario": {"slot_s": slot, "start_heading_jitter_deg": 180.0},
        "acoustics": {"charging_s": slot, "data_s": slot},
    }


@pytest.mark.parametrize(
    "data",
    [
        # fastest flow (40 m/s x 0.03125 s = 1.25 m), 7.95 N s^2/m^2 x 40 m/s x 0.03125 s = 9.9 kg
        corner(20.0, 0.0053, [0.0, 20.0], 0.03125, 25.0),
        # slowest, least drag (4.65 N s^2/m^2), head current, longest timestep
        corner(0.5, 0.0031, [-0.5, 0.0], 0.25, 25.0),
        # most drag (1650 N s^2/m^2 x 1 m/s x 0.006 s = 9.9 kg)
        corner(0.5, 0.1, [0.0, 0.5], 0.006, 24.0, wetted_area_m2=30.0, water_density_kgpm3=1100.0),
        # 7.95 N s^2/m^2 x 5 m/s x 0.25 s = 9.9 kg; 10,000 substeps of the longest slot
        corner(2.5, 0.0053, [0.0, 2.5], 0.25, 2500.0),
    ],
)
def test_the_mujoco_backend_at_the_corners_of_the_accepted_ranges(data):
    fly(data, "mujoco", slots=3, seed=1)
