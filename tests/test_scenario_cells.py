"""The scenario VecEnv's cells: each steps as its batch alone, and TensorBoard gets every
cell's reward terms and episode metrics from a real PPO run."""

import dataclasses

import numpy as np
import pytest
from stable_baselines3 import PPO
from stable_baselines3.common.callbacks import BaseCallback
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from iout_mj.agents.token_policy import TokenPolicy
from iout_mj.config import Config, RewardWeights
from iout_mj.envs import KinematicVecEnv
from iout_mj.envs.batch import MissionBatch
from iout_mj.envs.scenario_vec_env import ScenarioVecEnv
from iout_mj.mission.tokens import K_MAX
from iout_mj.schema import ConfigError
from iout_mj.training.callbacks import MissionLoggerCallback

TERMS = (  # the reward terms by their literal names (mission/rewards.py)
    "docking_progress",
    "aoi",
    "fairness",
    "boundary",
    "stall",
    "energy_margin",
    "infeasible_uplink",
    "collision",
    "docking",
    "deadline",
    "undocked_at_end",
    "aoi_after_mission",
)


def noise(cfg: Config, model: str) -> Config:
    return cfg.replace(acoustics=dataclasses.replace(cfg.acoustics, noise_model=model))


def cell_actions(rng, venv, n_auvs=2):
    """Random actions, the node indices of each environment inside its cell's K."""
    rows = []
    for c in venv.cells:
        high = [11, 7, c.n_nodes, c.n_nodes] * n_auvs
        rows.append(rng.integers(0, high, size=(c.batch.n_envs, 4 * n_auvs)))
    return np.concatenate(rows)


def test_cells_name_their_k_noise_batch_and_environments():
    base = Config()
    venv = ScenarioVecEnv([(3, base), (5, noise(base, "wenz")), (3, base)], envs_per_cell=2)
    assert [c.name for c in venv.cells] == ["k3_flat_0", "k5_wenz", "k3_flat_2"]
    assert [(c.n_nodes, c.noise_model) for c in venv.cells] == [
        (3, "flat"),
        (5, "wenz"),
        (3, "flat"),
    ]
    assert [(c.envs.start, c.envs.stop) for c in venv.cells] == [(0, 2), (2, 4), (4, 6)]
    assert [c.batch.mission.n_nodes for c in venv.cells] == [3, 5, 3]
    assert venv.cells[1].batch.cfg.acoustics.noise_model == "wenz"
    assert venv.num_envs == 6 and venv.term_values().shape == (6, len(TERMS))
    three = base.replace(scenario=dataclasses.replace(base.scenario, n_auvs=3))
    with pytest.raises(ConfigError, match=r"cells\[1\] \(K=4\) has .*'n_auvs': 3.*'n_auvs': 2"):
        ScenarioVecEnv([(3, base), (4, three)])
    with pytest.raises(ValueError, match="accepted a non-empty list"):
        ScenarioVecEnv([])


def test_each_cell_steps_as_its_batch_alone_with_the_same_seed():
    base = Config()
    cells = [(3, base), (6, noise(base, "wenz")), (4, base)]
    venv = ScenarioVecEnv(cells, envs_per_cell=2, seed=11)
    alone = [
        MissionBatch(2, "kinematic", 2, k, "random", cfg, seed, observation="tokens")
        for (k, cfg), seed in zip(cells, venv.cell_seeds, strict=True)
    ]
    obs = venv.reset()
    for c, batch in zip(venv.cells, alone, strict=True):
        batch.restart()
        np.testing.assert_array_equal(obs[c.envs], batch.observe())
    rng = np.random.default_rng(0)
    ended = 0
    for _ in range(70):  # past T_max = 55: every environment ends an episode and restarts
        actions = cell_actions(rng, venv)
        obs, rewards, dones, infos = venv.step(actions)
        for c, batch in zip(venv.cells, alone, strict=True):
            step = batch.step(actions[c.envs])
            np.testing.assert_array_equal(obs[c.envs], step.obs)
            np.testing.assert_array_equal(rewards[c.envs], step.rewards.astype(np.float32))
            np.testing.assert_array_equal(dones[c.envs], step.terminated | step.truncated)
            np.testing.assert_array_equal(venv.term_values()[c.envs], batch.mission.term_values)
            for e, (_, final) in step.ended.items():
                assert infos[c.envs.start + e]["metrics"] == final["metrics"]
                ended += 1
    assert ended >= 6
    # the cells' streams differ, and a seed given to the VecEnv repeats them all
    assert len(set(venv.cell_seeds)) == 3
    venv.seed(11)
    np.testing.assert_array_equal(venv.reset(), ScenarioVecEnv(cells, 2, seed=11).reset())


class ReferenceLog(BaseCallback):
    """What every rollout should log, by plain loops over each cell's own batch and infos."""

    def __init__(self, venv: ScenarioVecEnv):
        super().__init__()
        self.venv, self.expected = venv, {}

    def _on_rollout_start(self) -> None:
        self.terms = {c.name: {t: [] for t in TERMS} for c in self.venv.cells}
        self.episodes = {c.name: [] for c in self.venv.cells}

    def _on_step(self) -> bool:
        for c in self.venv.cells:
            for t, values in c.batch.mission.terms.items():
                self.terms[c.name][t].extend(values.tolist())
            for e in range(c.envs.start, c.envs.stop):
                if "metrics" in self.locals["infos"][e]:
                    self.episodes[c.name].append(self.locals["infos"][e]["metrics"])
        return True

    def _on_rollout_end(self) -> None:
        tags = {}
        for name, terms in self.terms.items():
            for t, values in terms.items():
                tags[f"cell/{name}/reward/{t}"] = np.mean(values)
            m = self.episodes[name]
            tags[f"cell/{name}/episode/mean_aoi"] = np.mean([x["mean_aoi"] for x in m])
            tags[f"cell/{name}/episode/docking_rate"] = np.mean([all(x["docked"]) for x in m])
            tags[f"cell/{name}/episode/jain"] = np.mean([x["jain"] for x in m])
            tags[f"cell/{name}/episode/delivered_bits"] = np.mean([x["delivered_bits"] for x in m])
        for t in TERMS:
            tags[f"reward/{t}"] = np.mean([v for terms in self.terms.values() for v in terms[t]])
        every = [x for m in self.episodes.values() for x in m]
        tags["episode/mean_aoi"] = np.mean([x["mean_aoi"] for x in every])
        self.expected[self.num_timesteps] = tags


def scalars(folder) -> dict[str, dict[int, float]]:
    """Every scalar of the one TensorBoard run under `folder`: tag -> {step: value}."""
    (run,) = [p for p in folder.iterdir() if p.is_dir()]
    events = EventAccumulator(str(run), size_guidance={"scalars": 0})
    events.Reload()
    return {tag: {s.step: s.value for s in events.Scalars(tag)} for tag in events.Tags()["scalars"]}


def test_mujoco_cells_stepped_on_two_threads_step_as_in_turn():
    base = Config()
    cells = [(3, base), (5, noise(base, "wenz")), (4, base)]
    runs = []
    for nthread in (0, 2):
        venv = ScenarioVecEnv(cells, envs_per_cell=1, backend="mujoco", seed=5, nthread=nthread)
        assert (venv._pool is None) == (nthread == 0)
        rng = np.random.default_rng(1)
        out = [venv.reset()]
        for _ in range(3):
            obs, rewards, _, _ = venv.step(cell_actions(rng, venv))
            out += [obs, rewards[:, None]]
        venv.close()
        runs.append(out)
    for a, b in zip(*runs, strict=True):
        np.testing.assert_array_equal(a, b)


def test_a_ppo_run_logs_every_cells_reward_terms_and_episodes(tmp_path):
    base = Config()
    zero = RewardWeights(**{f.name: 0.0 for f in dataclasses.fields(RewardWeights)})
    silent = base.replace(reward=dataclasses.replace(base.reward, weights=zero))
    cells = [(3, base), (5, base), (3, noise(base, "wenz")), (5, noise(silent, "wenz"))]
    venv = ScenarioVecEnv(cells, envs_per_cell=1, seed=3)
    reference = ReferenceLog(venv)
    model = PPO(
        TokenPolicy,
        venv,
        n_steps=64,
        batch_size=64,
        n_epochs=1,
        seed=0,
        device="cpu",
        policy_kwargs={"k_max": K_MAX, "width": 16},
        tensorboard_log=str(tmp_path),
    )
    model.learn(512, callback=[MissionLoggerCallback(0), reference], tb_log_name="ppo")
    logged = scalars(tmp_path)
    assert sorted(reference.expected) == [256, 512]  # two rollouts of 64 steps x 4 envs
    for step, tags in reference.expected.items():
        for tag, value in tags.items():
            assert logged[tag][step] == pytest.approx(value, rel=1e-5, abs=1e-6), (tag, step)
    names = ("k3_flat", "k5_flat", "k3_wenz", "k5_wenz")
    assert {t.split("/")[1] for t in logged if t.startswith("cell/")} == set(names)
    for step in (256, 512):
        # every term of a cell whose weights are all zero is 0: no cell's values leak into it
        assert all(logged[f"cell/k5_wenz/reward/{t}"][step] == 0.0 for t in TERMS)
        assert all(logged[f"cell/{n}/reward/aoi"][step] < 0.0 for n in names[:3])
        cells_mean = np.mean([logged[f"cell/{n}/reward/aoi"][step] for n in names])
        assert logged["reward/aoi"][step] == pytest.approx(cells_mean, rel=1e-5)


def test_a_single_scenario_run_logs_the_terms_without_cells(tmp_path):
    venv = KinematicVecEnv(2, n_auvs=1, n_nodes=7, seed=0)
    model = PPO(
        "MlpPolicy", venv, n_steps=64, batch_size=64, seed=0, device="cpu", tensorboard_log=tmp_path
    )
    model.learn(128, callback=MissionLoggerCallback(0), tb_log_name="ppo")
    logged = scalars(tmp_path)
    assert {f"reward/{t}" for t in TERMS} <= set(logged)
    assert "episode/mean_aoi" in logged and "time/fps_run" in logged
    assert not any(t.startswith("cell/") for t in logged)
    assert logged["reward/aoi"][128] < 0.0
