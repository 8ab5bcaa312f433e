"""λ schedule (Eq. 11), threshold trigger (Eq. 12), bounded projection (Eq. 13), annotation cache."""

import numpy as np
import pytest

from mrguide.policies.experts import AnnotatorNoise, FileExpert, OracleExpert, SimulatedAnnotator
from mrguide.policies.guidance import (
    Annotation,
    AnnotationCache,
    AnnotationError,
    RunningMedianReference,
    ThresholdTrigger,
    bounded_projection,
    expert_ratio,
)
from mrguide.task import TaskConfig, observation, phase_target


def test_expert_ratio_schedule():
    assert expert_ratio(0, 20_000) == pytest.approx(0.9)
    assert expert_ratio(10_000, 20_000) == pytest.approx(0.5)
    assert expert_ratio(20_000, 20_000) == pytest.approx(0.1)
    assert expert_ratio(30_000, 20_000) == pytest.approx(0.1)  # floored at λ_min
    assert expert_ratio(5_000, 20_000, 0.8, 0.2) == pytest.approx(0.8 - 0.25 * 0.6)


def test_threshold_trigger_on_crafted_rewards():
    trig = ThresholdTrigger(-5.0)
    assert [trig.update(r) for r in (-1.0, -2.0, 3.0, -4.0, -1.5)] == [False, False, False, False, True]
    trig.reset()
    assert not trig.update(-4.99)
    assert trig.update(-0.02)  # -5.01 < -5
    trig.reset()
    assert not any(trig.update(r) for r in (-0.4,) * 12)  # -4.8 never crosses


def test_bounded_projection_inside_kept_outside_on_sphere():
    ref = np.array([0.5, 0.0, 0.2])
    inside = ref + [0.01, -0.01, 0.0]
    assert np.allclose(bounded_projection(inside, ref, 0.03), inside)
    outside = ref + [0.3, 0.4, 0.0]  # 0.5 m away
    out = bounded_projection(outside, ref, 0.03)
    assert np.linalg.norm(out - ref) == pytest.approx(0.03)
    assert np.allclose((out - ref) / 0.03, [0.6, 0.8, 0.0])  # direction kept
    with pytest.raises(AnnotationError):
        bounded_projection(np.array([np.nan, 0, 0]), ref, 0.03)
    with pytest.raises(ValueError):
        bounded_projection(inside, ref, 0.0)


def _obs(phase, obj=(0.5, -0.1, 0.025), goal=(0.5, 0.2, 0.025), tcp=(0.5, 0.1, 0.3)):
    return observation(np.array(tcp), -1, phase / 5, np.array(obj), np.array(goal))


def test_cache_reuses_matching_observations_and_persists(tmp_path):
    path = tmp_path / "ann.jsonl"
    cache = AnnotationCache(0.005, path)
    ann = Annotation(np.array([0.5, -0.1, 0.13]), -1.0)
    cache.insert(_obs(0), ann)
    # the arm elsewhere, object within tolerance: same waypoint
    hit = cache.lookup(_obs(0, obj=(0.503, -0.1, 0.025), tcp=(0.4, 0.0, 0.2)))
    assert hit is ann
    assert cache.lookup(_obs(0, obj=(0.51, -0.1, 0.025))) is None  # object moved 1 cm
    assert cache.lookup(_obs(1)) is None  # other phase
    # transport and release depend on the goal only
    cache.insert(_obs(3), Annotation(np.array([0.5, 0.2, 0.15]), 1.0))
    assert cache.lookup(_obs(3, obj=(0.4, 0.0, 0.1))) is not None
    fresh = AnnotationCache(0.005)
    assert fresh.load(path) == 2
    assert np.allclose(fresh.lookup(_obs(0)).target, ann.target)


def test_cache_load_skips_torn_last_line_but_refuses_corruption(tmp_path):
    path = tmp_path / "ann.jsonl"
    cache = AnnotationCache(0.005, path)
    cache.insert(_obs(0), Annotation(np.array([0.5, -0.1, 0.13]), -1.0))
    with path.open("a") as fh:
        fh.write('{"obs": [0.1, 0.2')  # crash mid-write
    assert AnnotationCache().load(path) == 1
    path.write_text('garbage\n' + path.read_text())
    with pytest.raises(AnnotationError, match=":1: bad annotation record"):
        AnnotationCache().load(path)


def test_simulated_annotator_noise_and_outliers():
    task = TaskConfig()
    exact = OracleExpert(task).annotate(_obs(0)).target
    noisy = SimulatedAnnotator(task, AnnotatorNoise(sigma=0.02), seed=1)
    errs = np.array([noisy.annotate(_obs(0)).target - exact for _ in range(2000)])
    assert errs.std(axis=0) == pytest.approx([0.02] * 3, rel=0.1)
    biased = SimulatedAnnotator(task, AnnotatorNoise(bias=(0.01, 0.0, -0.02)), seed=1)
    assert np.allclose(biased.annotate(_obs(0)).target - exact, [0.01, 0.0, -0.02])
    outl = SimulatedAnnotator(task, AnnotatorNoise(outlier_rate=0.1, outlier_scale=0.2), seed=2)
    big = np.mean([np.linalg.norm(outl.annotate(_obs(0)).target - exact) > 0.05 for _ in range(2000)])
    assert 0.07 < big < 0.13


def test_running_median_reference_follows_bias_not_outliers():
    task = TaskConfig()
    ref = RunningMedianReference(task, window=25)
    obs = _obs(0)
    nominal = phase_target(0, obs[5:8], obs[8:11], task)
    rng = np.random.default_rng(0)
    for k in range(25):
        err = np.array([0.02, 0.0, 0.0]) + rng.normal(0, 0.002, 3)
        if k % 5 == 0:
            err = err + [0.0, 0.5, 0.0]  # 20 % gross outliers
        ref.observe(obs, Annotation(nominal + err, -1.0))
    assert np.allclose(ref.reference(obs) - nominal, [0.02, 0.0, 0.0], atol=0.004)


def test_file_expert(tmp_path):
    path = tmp_path / "rec.jsonl"
    AnnotationCache(0.005, path).insert(_obs(2), Annotation(np.array([0.5, -0.1, 0.15]), 1.0))
    fe = FileExpert(path)
    assert np.allclose(fe.annotate(_obs(2)).target, [0.5, -0.1, 0.15])
    with pytest.raises(AnnotationError, match="no recorded annotation"):
        fe.annotate(_obs(4))
    with pytest.raises(AnnotationError, match="not found"):
        FileExpert(tmp_path / "missing.jsonl")
