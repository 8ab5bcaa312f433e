"""What the policy sees of the part while it trains (`mrguide.part_perception`): the pose source's errors through the
runtime's rules, while the task model judges the twin's truth."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from mrguide.part_perception import PerceptionConfig, StillPartFilter
from mrguide.task import OBS_OBJECT
from mrguide.twin.env import EnvConfig, PickPlaceEnv


def _env(perception: PerceptionConfig) -> PickPlaceEnv:
    cfg = EnvConfig()
    return PickPlaceEnv(replace(cfg, twin=replace(cfg.twin, perception=perception)))


def _episode(env: PickPlaceEnv, seed: int) -> list[tuple[np.ndarray, np.ndarray, bool]]:
    """(seen, true part, held) per decision of the scripted expert's episode."""
    obs, _ = env.reset(seed=seed)
    out = [(obs[OBS_OBJECT].copy(), env.scene.object_position(), False)]
    while True:
        obs, _, term, trunc, info = env.step(env.expert_action())
        out.append((obs[OBS_OBJECT].copy(), env.scene.object_position(), info["part_present"]))
        if term or trunc:
            return out


def test_the_filter_averages_the_looks_and_starts_afresh_where_the_part_moved():
    f = StillPartFilter()
    assert np.allclose(f.update([0.0, 0.0, 0.0]), 0.0)
    assert np.allclose(f.update([0.004, 0.002, 0.0]), [0.002, 0.001, 0.0]) and f.looks == 2
    assert np.allclose(f.update([0.1, 0.0, 0.0]), [0.1, 0.0, 0.0]) and f.looks == 1
    assert np.allclose(f.update([0.1, 0.0, 0.0]), [0.1, 0.0, 0.0]) and f.looks == 1  # the same frame again
    assert np.allclose(f.update([0.104, 0.0, 0.0]), [0.102, 0.0, 0.0]) and f.looks == 2


def test_exact_perception_sees_the_part_where_it_is():
    env = _env(PerceptionConfig(bias=0.0, noise=0.0))
    try:
        assert all(np.allclose(seen, true, atol=1e-6) for seen, true, _ in _episode(env, 3))
    finally:
        env.close()


HMD = PerceptionConfig(bias=0.0015, noise=0.005)  # configs/runs/perception.toml


def test_the_policy_sees_the_resting_part_through_a_bias_per_episode_and_the_held_part_under_the_cup():
    env = _env(HMD)
    try:
        biases = []
        for seed in range(6):
            steps = _episode(env, seed)
            resting = [seen - true for seen, true, held in steps if not held][:5]
            biases.append(resting[-1])
            assert any(np.linalg.norm(e) > 1e-4 for e in resting)  # never the truth itself
            held = [(seen, true) for seen, true, h in steps if h]
            assert held, "the scripted expert grasps"
            tcp_based = [seen for seen, _ in held]
            assert all(
                np.linalg.norm(s[:2] - t[:2]) < 0.006 for s, t in zip(tcp_based, [t for _, t in held], strict=True)
            )
        assert np.std([b[0] for b in biases]) > 5e-4  # each episode draws a bias of its own
    finally:
        env.close()


def test_a_restored_episode_sees_the_part_as_it_saw_it():
    env = _env(HMD)
    try:
        env.reset(seed=4)
        snap = env.snapshot()
        actions, first = [], []
        for _ in range(12):
            actions.append(env.expert_action())
            first.append(env.step(actions[-1])[0])
        env.restore(snap)
        again = [env.step(a)[0] for a in actions]
        assert all(np.array_equal(x, y) for x, y in zip(first, again, strict=True))
        env.discard(snap)
    finally:
        env.close()


def test_a_part_gripped_where_a_person_taught_is_seen_hanging_from_that_grip():
    """The keep-out block gripped 37 mm off its middle (a taught grasp): while held, the policy sees the part's centre
    that far from the cup, where it is, not under the cup."""
    from mrguide.policies.train_config import RunConfig
    from tests.policies.test_taught_grasp import TAUGHT

    run = RunConfig.load(Path(__file__).resolve().parents[2] / "configs" / "parts" / "keepout_block.toml")
    env = PickPlaceEnv(replace(run.env, twin=replace(run.env.twin, perception=HMD)))
    try:
        env.teach(replace(env.task_cfg, grasp=tuple(TAUGHT)))
        held = [(seen, true) for seen, true, h in _episode(env, 1) if h]
    finally:
        env.close()
    assert held, "the scripted expert grasps at the taught point"
    assert all(np.linalg.norm(s[:2] - t[:2]) < 0.006 for s, t in held)
