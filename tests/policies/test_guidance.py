"""λ schedule (Eq. 11), threshold trigger (Eq. 12), bounded projection (Eq. 13), annotation cache."""

import numpy as np
import pytest

from mrguide.policies.annotations import Annotation, AnnotationCache, AnnotationError
from mrguide.policies.experts import AnnotatorNoise, FileExpert, OracleExpert, SimulatedAnnotator
from mrguide.policies.guidance import (
    RunningMedianReference,
    ThresholdTrigger,
    bounded_projection,
    expert_ratio,
)
from mrguide.robot import Workspace, load_robot
from mrguide.task import TaskConfig, observation, phase_target

WIDE = Workspace((-5.0, -5.0, -5.0), (5.0, 5.0, 5.0))  # no clamping: noise statistics as drawn


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
    assert hit.annotation is ann and hit.index == 0
    assert cache.lookup(_obs(0, obj=(0.51, -0.1, 0.025))) is None  # object moved 1 cm
    assert cache.lookup(_obs(1)) is None  # other phase
    # transport and release depend on the goal only
    cache.insert(_obs(3), Annotation(np.array([0.5, 0.2, 0.15]), 1.0))
    assert cache.lookup(_obs(3, obj=(0.4, 0.0, 0.1))) is not None
    fresh = AnnotationCache(0.005)
    assert fresh.load(path) == 2
    assert np.allclose(fresh.lookup(_obs(0)).annotation.target, ann.target)


def test_cache_remark_supersedes_and_survives_reload(tmp_path):
    path = tmp_path / "ann.jsonl"
    cache = AnnotationCache(0.005, path)
    first = cache.insert(_obs(1), Annotation(np.array([0.5, -0.1, 0.08]), 1.0, "live", {"client": "bot"}))
    cache.insert(_obs(3), Annotation(np.array([0.5, 0.2, 0.15]), 1.0))
    again = cache.insert(_obs(1), Annotation(np.array([0.5, -0.1, 0.047]), 1.0, "live"), supersedes=first)
    assert cache.lookup(_obs(1)).index == again and len(cache) == 2
    fresh = AnnotationCache(0.005, path)
    assert fresh.load(path) == 2
    hit = fresh.lookup(_obs(1))
    assert hit.index == again and np.allclose(hit.annotation.target, [0.5, -0.1, 0.047])
    lines = path.read_text().splitlines()
    assert '"client": "bot"' in lines[0] and '"supersedes": 0' in lines[2]


@pytest.mark.parametrize(
    "record, reason",
    [
        ("[1, 2]", "JSON object"),
        ('{"obs": [0.1], "target": [0.5, 0, 0.1], "grip": 1}', "11 finite numbers"),
        ('{"obs": OBS, "target": [NaN, 0, 0.1], "grip": 1}', "3 finite numbers"),
        ('{"obs": OBS, "target": [0.5, 0, 0.1], "grip": null}', "gripper command"),
        ('{"obs": OBS, "target": [0.5, 0, 0.1]}', "no 'grip'"),
        ('{"obs": OBS, "target": "here", "grip": 1}', "target"),
        ('{"obs": OBS, "target": [0.5, 0, 0.1], "grip": 1, "supersedes": 7}', "earlier record"),
    ],
)
def test_cache_refuses_bad_records_naming_the_line(tmp_path, record, reason):
    path = tmp_path / "ann.jsonl"
    good = '{"obs": OBS, "target": [0.5, 0, 0.1], "grip": 1}'
    obs = str(_obs(0).tolist())
    path.write_text(good.replace("OBS", obs) + "\n" + record.replace("OBS", obs) + "\n")
    with pytest.raises(AnnotationError, match=reason) as err:
        AnnotationCache().load(path)
    assert f"{path}:2:" in str(err.value)


def test_cache_repair_cuts_a_torn_tail_so_the_next_record_is_whole(tmp_path):
    path = tmp_path / "ann.jsonl"
    cache = AnnotationCache(0.005, path)
    cache.insert(_obs(0), Annotation(np.array([0.5, -0.1, 0.13]), -1.0))
    with path.open("a") as fh:
        fh.write('{"obs": [0.1, 0.2')  # crash mid-write
    resumed = AnnotationCache(0.005, path)
    assert resumed.load(path, repair=True) == 1
    resumed.insert(_obs(3), Annotation(np.array([0.5, 0.2, 0.15]), 1.0))
    assert AnnotationCache().load(path) == 2  # no record glued onto the torn line


def test_cache_repair_gives_a_whole_last_record_its_lost_newline(tmp_path):
    """A record written whole but without its newline (a full disk, a crash between the two writes): the resumed
    run's next record would be glued onto it and every later load would fail."""
    path = tmp_path / "ann.jsonl"
    cache = AnnotationCache(0.005, path)
    cache.insert(_obs(0), Annotation(np.array([0.5, -0.1, 0.13]), -1.0))
    path.write_bytes(path.read_bytes().rstrip(b"\n"))
    resumed = AnnotationCache(0.005, path)
    assert resumed.load(path, repair=True) == 1
    resumed.insert(_obs(3), Annotation(np.array([0.5, 0.2, 0.15]), 1.0))
    assert AnnotationCache().load(path) == 2 and path.read_bytes().count(b"\n") == 2


def test_cache_load_skips_torn_last_line_but_refuses_corruption(tmp_path):
    path = tmp_path / "ann.jsonl"
    cache = AnnotationCache(0.005, path)
    cache.insert(_obs(0), Annotation(np.array([0.5, -0.1, 0.13]), -1.0))
    with path.open("a") as fh:
        fh.write('{"obs": [0.1, 0.2')  # crash mid-write
    assert AnnotationCache().load(path) == 1
    path.write_text("garbage\n" + path.read_text())
    with pytest.raises(AnnotationError, match=":1: not JSON"):
        AnnotationCache().load(path)


def test_simulated_annotator_noise_and_outliers():
    task = TaskConfig()
    exact = OracleExpert(task).annotate(_obs(0)).target
    noisy = SimulatedAnnotator(task, AnnotatorNoise(sigma=0.02), WIDE, seed=1)
    errs = np.array([noisy.annotate(_obs(0)).target - exact for _ in range(2000)])
    assert errs.std(axis=0) == pytest.approx([0.02] * 3, rel=0.1)
    biased = SimulatedAnnotator(task, AnnotatorNoise(bias=(0.01, 0.0, -0.02)), WIDE, seed=1)
    assert np.allclose(biased.annotate(_obs(0)).target - exact, [0.01, 0.0, -0.02])
    outl = SimulatedAnnotator(task, AnnotatorNoise(outlier_rate=0.1, outlier_scale=0.2), WIDE, seed=2)
    big = np.mean([np.linalg.norm(outl.annotate(_obs(0)).target - exact) > 0.05 for _ in range(2000)])
    assert 0.07 < big < 0.13


def test_simulated_annotator_marks_inside_the_workspace_box_only():
    ws = load_robot().workspace
    marks = SimulatedAnnotator(TaskConfig(), AnnotatorNoise(sigma=0.1), ws, seed=3)
    targets = np.array([marks.annotate(_obs(1)).target for _ in range(500)])
    assert np.all(targets >= ws.lo) and np.all(targets <= ws.hi)
    assert np.mean(targets[:, 2] == ws.lo[2]) > 0.2  # grasp marks below the box floor land on it


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
    replayed = fe.annotate(_obs(2))
    assert np.allclose(replayed.target, [0.5, -0.1, 0.15]) and replayed.source == "file"
    with pytest.raises(AnnotationError, match="no recorded annotation"):
        fe.annotate(_obs(4))
    with pytest.raises(AnnotationError, match="not found"):
        FileExpert(tmp_path / "missing.jsonl")


class _Recorder:
    """An expert source that marks a fixed (unreachable) point and records what it was asked."""

    def __init__(self, answers):
        self.answers = list(answers)
        self.previous = []

    def annotate(self, obs, previous=None):
        self.previous.append(previous)
        target = self.answers.pop(0)
        return None if target is None else Annotation(np.array(target), 1.0, "live")


def _guided(source, tmp_path, reask_after):
    from mrguide.policies.guidance import NominalReference
    from mrguide.policies.guided_expert import GuidedExpert

    task = TaskConfig()
    cache = AnnotationCache(0.005, tmp_path / "ann.jsonl")
    return GuidedExpert(
        source,
        NominalReference(task),
        cache,
        0.05,
        task,
        load_robot().workspace.to_normalized,
        reask_after,
        marks="phases",
    ), cache


def test_a_waypoint_not_reached_is_asked_again_and_supersedes_the_first(tmp_path):
    src = _Recorder([[0.5, -0.1, 0.06], [0.5, -0.1, 0.047]])
    expert, cache = _guided(src, tmp_path, reask_after=15)
    expert.begin_demonstration()
    obs = _obs(1)  # grasp phase; the arm never gets there, so the phase does not advance
    actions = [expert.action(obs).executed for _ in range(15)]  # the mark is followed for 15 steps
    assert (
        src.previous == [None]
        and expert.counts.asked == 1
        and expert.counts.reused == 14
        and expert.counts.remarks == 0
    )
    assert np.allclose(actions[0], actions[14])
    again = expert.action(obs).executed  # 16th step on the same waypoint: asked again, with the old mark
    assert (
        expert.counts.remarks == 1
        and expert.counts.asked == 2
        and np.allclose(src.previous[1].target, [0.5, -0.1, 0.06])
    )
    assert not np.allclose(again, actions[0]) and cache.lookup(obs).index == 1 and len(cache) == 1
    fresh = AnnotationCache(0.005)
    fresh.load(tmp_path / "ann.jsonl")
    assert np.allclose(fresh.lookup(obs).annotation.target, [0.5, -0.1, 0.047])


def test_reask_disabled_and_a_new_demonstration_restarts_the_count(tmp_path):
    src = _Recorder([[0.5, -0.1, 0.06]])
    expert, _ = _guided(src, tmp_path, reask_after=0)
    for _ in range(40):
        expert.action(_obs(1))
    assert expert.counts.asked == 1 and expert.counts.remarks == 0
    src = _Recorder([[0.5, -0.1, 0.06]])
    expert, _ = _guided(src, tmp_path / "..", reask_after=15)
    for _ in range(3):
        expert.begin_demonstration()
        for _ in range(10):  # 10 steps per demonstration: never 15 in a row
            expert.action(_obs(1))
    assert expert.counts.asked == 1 and expert.counts.remarks == 0


def test_nobody_answering_gives_no_action(tmp_path):
    expert, cache = _guided(_Recorder([None]), tmp_path, reask_after=15)
    assert expert.action(_obs(0)) is None and len(cache) == 0 and expert.counts.asked == 1


def test_action_noise_perturbs_every_action_afresh_after_the_projection(tmp_path):
    from mrguide.policies.guidance import NominalReference
    from mrguide.policies.guided_expert import GuidedExpert

    task, ws = TaskConfig(), load_robot().workspace
    exact = Annotation(np.array([0.5, -0.1, 0.13]), -1.0)

    class Exact:
        def annotate(self, obs, previous=None):
            return exact

    def steps(sigma, seed=0):
        expert = GuidedExpert(
            Exact(),
            NominalReference(task),
            AnnotationCache(0.005),
            0.05,
            task,
            ws.to_normalized,
            0,
            sigma,
            seed,
            marks="phases",
        )
        out = [expert.action(_obs(0)) for _ in range(400)]
        return np.array([s.executed[:3] for s in out]), np.array([s.stored[:3] for s in out])

    clean, clean_labels = steps(0.0)
    assert np.allclose(clean, clean[0]) and np.array_equal(clean, clean_labels)  # one mark, one action
    executed, labels = steps(0.03)
    assert np.allclose(executed, clean)  # the arm follows the clean action, the stored label is perturbed
    err = ws.to_cartesian(labels) - ws.to_cartesian(clean)
    assert err.std(axis=0) == pytest.approx([0.03] * 3, rel=0.15)  # fresh per step, not clipped to Δ = 5 cm
    assert np.abs(err).max() > 0.05 and len({tuple(r) for r in labels}) == 400
    assert np.array_equal(steps(0.03)[1], labels) and not np.array_equal(steps(0.03, seed=1)[1], labels)


def test_action_noise_never_changes_the_vacuum_command(tmp_path):
    """Release at the place pose: the clean waypoint is reached, so the clean command opens the vacuum.

    The noise moves the motion target only; a release decided on the perturbed target (‖tcp − noisy‖
    > ε/2 for most draws at σ = 1 cm) kept the vacuum on at the goal, and no policy learned to let go.
    """
    from mrguide.policies.guidance import NominalReference
    from mrguide.policies.guided_expert import GuidedExpert

    task, ws = TaskConfig(), load_robot().workspace
    obs = _obs(4, tcp=(0.5, 0.2, 0.05))  # the TCP at the nominal place pose, which is also the mark
    place = obs[0:3].copy()

    class AtPlace:
        def annotate(self, obs, previous=None):
            return Annotation(place, -1.0)

    expert = GuidedExpert(
        AtPlace(),
        NominalReference(task),
        AnnotationCache(0.005),
        0.05,
        task,
        ws.to_normalized,
        0,
        0.01,
        0,
        marks="phases",
    )
    steps = [expert.action(obs) for _ in range(200)]
    assert all(s.executed[3] == -1.0 and s.stored[3] == -1.0 for s in steps)
    assert len({tuple(s.stored[:3]) for s in steps}) == 200  # the motion is still perturbed afresh


def test_action_noise_keeps_the_grasp_height_label_unbiased(tmp_path):
    """A grasp mark 5 mm above the box's floor: the perturbed labels are not clipped to the box, so they average to
    the mark and may leave the box (clipping would cut off the noise's downward half and lift the labels' mean by
    about σ·φ(0), ~18 mm at σ = 5 cm)."""
    from mrguide.policies.guidance import NominalReference
    from mrguide.policies.guided_expert import GuidedExpert

    task, ws = TaskConfig(), load_robot().workspace
    mark = np.array([0.5, -0.1, ws.lo[2] + 0.005])

    class Grasp:
        def annotate(self, obs, previous=None):
            return Annotation(mark, 1.0)

    expert = GuidedExpert(
        Grasp(),
        NominalReference(task),
        AnnotationCache(0.005),
        0.05,
        task,
        ws.to_normalized,
        0,
        0.05,
        0,
        marks="phases",
    )
    obs = _obs(1, tcp=(0.5, -0.1, 0.06), obj=(0.5, -0.1, ws.lo[2] + 0.005 - 0.5 * task.object_height))
    heights = ws.to_cartesian(np.array([expert.action(obs).stored[:3] for _ in range(4000)]))[:, 2]
    assert heights.min() < ws.lo[2] - 0.05
    assert abs(heights.mean() - mark[2]) < 0.003
