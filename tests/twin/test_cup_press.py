"""Pressing the cup onto the part's edge: a rigid cup shoves the part, the level-compensator's does not (docs/twin.md).

The grasp search of a demonstration presses beside where it first pressed; with the lip's 5 mm window
(`mrguide.seal`) a probe only finds the seal if the presses before it left the part where it was."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from mrguide.task import annotation_action
from mrguide.twin.env import EnvConfig, PickPlaceEnv


def _shove_mm(stroke: float, offset: float) -> float:
    """How far (mm, laterally) pressing the cup `offset` m beside the part's centre, down to the workspace floor
    (5 mm into the part), moves the part."""
    cfg = EnvConfig()
    env = PickPlaceEnv(replace(cfg, twin=replace(cfg.twin, cup=replace(cfg.twin.cup, stroke=stroke))))
    try:
        obs, _ = env.reset(seed=0)
        start = env.scene.object_position()
        above = start + [offset, 0.0, 0.075]  # the true part: the obs sees it through the pose errors
        for target, grip, n in ((above, -1.0, 10), (above - [0, 0, 0.04], 1.0, 2), (above - [0, 0, 0.1], 1.0, 8)):
            for _ in range(n):
                obs, *_ = env.step(annotation_action(obs, target, grip, env.task_cfg, env.workspace.to_normalized))
        return 1e3 * float(np.linalg.norm(env.scene.object_position()[:2] - start[:2]))
    finally:
        env.close()


@pytest.mark.parametrize("offset", [0.006, 0.01])
def test_a_press_beside_the_seal_moves_the_part_on_a_rigid_cup_and_not_on_the_compensator(offset):
    rigid, compensated = _shove_mm(0.0, offset), _shove_mm(EnvConfig().twin.cup.stroke, offset)
    print(
        f"pressed {1e3 * offset:.0f} mm beside the centre: the part moved {rigid:.1f} mm (rigid), {compensated:.1f} mm"
    )
    assert rigid > 3.0 and compensated < 1.0, (rigid, compensated)
