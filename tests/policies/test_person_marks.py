"""A person's marks: the headset error model, the waypoints of exact marks, and their fusion."""

import numpy as np
import pytest

from mrguide.config import ConfigError
from mrguide.policies.experts import AnnotatorNoise, OracleExpert, SimulatedAnnotator
from mrguide.policies.mark_fusion import MarkFusion
from mrguide.robot import Workspace
from mrguide.task import (
    GRASP_PRESS,
    PICK_PHASE,
    PLACE_PHASE,
    TaskConfig,
    mark_phase,
    oracle_target,
    phase_target,
    waypoint_from_mark,
)
from tests.policies.mark_scene import GOAL, OBJ, scene_obs

WIDE = Workspace((-5.0, -5.0, -5.0), (5.0, 5.0, 5.0))  # no clamping: noise statistics as drawn


def _errors(noise, seed, n=4000, point=(0.5, -0.1, 0.047)):
    ann = SimulatedAnnotator(TaskConfig(), noise, WIDE, seed=seed)
    obs = scene_obs(1, obj=np.array(point) - [0, 0, 0.022])
    exact = OracleExpert(TaskConfig()).annotate(obs).target
    return ann, np.array([ann.annotate(obs).target - exact for _ in range(n)])


def test_person_bias_is_drawn_once_per_run_and_differs_between_runs():
    a, errs = _errors(AnnotatorNoise(bias_sigma=0.007), seed=1, n=50)
    assert np.allclose(errs, errs[0]) and np.linalg.norm(errs[0]) > 1e-4  # every mark of the run shares it
    assert np.allclose(a.run_bias, errs[0])
    b, _ = _errors(AnnotatorNoise(bias_sigma=0.007), seed=2, n=1)
    assert not np.allclose(a.run_bias, b.run_bias)
    biases = np.array(
        [SimulatedAnnotator(TaskConfig(), AnnotatorNoise(bias_sigma=0.007), WIDE, seed=s).run_bias for s in range(400)]
    )
    assert biases.std(0) == pytest.approx([0.007] * 3, rel=0.15)


def test_person_error_is_larger_along_the_line_of_sight_than_across():
    noise = AnnotatorNoise(sigma_across=0.01, sigma_along=0.02)
    point = np.array([0.5, -0.1, 0.047])
    _, errs = _errors(noise, seed=3, point=tuple(point))
    u = point - np.array(noise.viewpoint)
    u /= np.linalg.norm(u)
    along = errs @ u
    across = errs - np.outer(along, u)
    assert along.std() == pytest.approx(0.02, rel=0.08)
    assert np.sqrt((across**2).sum(1).mean() / 2) == pytest.approx(0.01, rel=0.08)  # per axis across the sight line
    assert abs(along.mean()) < 0.002


def test_person_slips_are_rare_and_gross():
    _, errs = _errors(
        AnnotatorNoise(sigma_across=0.005, sigma_along=0.005, outlier_rate=0.03, outlier_scale=0.1), seed=4
    )
    gross = np.linalg.norm(errs, axis=1) > 0.05
    assert 0.015 < gross.mean() < 0.045


def test_isotropic_annotator_stream_is_unchanged_by_the_person_terms():
    """Fig. 7's annotator (sigma only) draws exactly as before the person model: 3 normals per mark."""
    _, errs = _errors(AnnotatorNoise(sigma=0.02), seed=5, n=3)
    rng = np.random.default_rng(5)
    assert np.allclose(errs, rng.normal(0.0, 0.02, (3, 3)))


@pytest.mark.parametrize(
    "field, value", [("bias_sigma", -0.01), ("sigma_along", float("nan")), ("viewpoint", (1.0, 2.0))]
)
def test_person_noise_refuses_bad_values(field, value):
    with pytest.raises(ConfigError, match=f"guidance.noise.{field}"):
        AnnotatorNoise(**{field: value})


def test_waypoints_from_exact_marks_are_the_task_models_targets():
    task = TaskConfig()
    pick = oracle_target(scene_obs(PICK_PHASE), task)[0]
    place = oracle_target(scene_obs(PLACE_PHASE), task)[0]
    assert np.allclose(pick, phase_target(1, OBJ, GOAL, task) - [0, 0, GRASP_PRESS])
    for phase in range(5):
        mark = pick if mark_phase(phase) == PICK_PHASE else place
        expected = oracle_target(scene_obs(phase), task)[0]
        assert np.allclose(waypoint_from_mark(phase, mark, task), expected), phase
    # the lift rises above the grasp point, not above wherever the part has moved to
    moved = scene_obs(2, obj=OBJ + [0.01, 0.0, 0.05])
    assert np.allclose(waypoint_from_mark(2, pick, task), [OBJ[0], OBJ[1], task.lift_height])
    assert not np.allclose(waypoint_from_mark(2, pick, task), oracle_target(moved, task)[0])


def test_fusion_averages_the_scatter_and_outvotes_a_slip():
    rng = np.random.default_rng(0)
    fusion = MarkFusion()
    offset = np.array([0.0, 0.0, 0.022])
    for k in range(40):
        at = np.array([0.4 + 0.2 * rng.random(), -0.1 + 0.2 * rng.random(), 0.025])
        err = rng.normal(0.0, 0.02, 3) if k != 7 else np.array([0.3, -0.2, 0.1])  # one slip
        fusion.add(PICK_PHASE, at, at + offset + err)
    assert np.abs(fusion.estimate(PICK_PHASE) - offset).max() < 0.01  # 2 cm per mark, 40 marks
    assert fusion.estimate(PLACE_PHASE) is None
    assert np.allclose(
        fusion.point(PICK_PHASE, [1.0, 2.0, 3.0]), np.array([1.0, 2.0, 3.0]) + fusion.estimate(PICK_PHASE)
    )
