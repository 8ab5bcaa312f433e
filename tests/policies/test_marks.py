"""A person's marks in pick-and-place demonstrations: two marks, the five waypoints, the search and what the cell measured."""

import numpy as np
import pytest

from mrguide.policies import waypoint_search as ws
from mrguide.policies.annotations import Annotation, AnnotationCache
from mrguide.policies.guidance import NominalReference
from mrguide.policies.guided_expert import GuidedExpert
from mrguide.policies.mark_fusion import MarkFusion
from mrguide.policies.pick_place_demo import RELEASE_DEPTH
from mrguide.robot import load_robot
from mrguide.task import (
    GRASP_PRESS,
    PICK_PHASE,
    PLACE_PHASE,
    Phase,
    TaskConfig,
    oracle_target,
    phase_from_progress,
    phase_target,
)
from tests.policies.mark_scene import GOAL, OBJ, scene_obs


def test_pick_place_bounds_the_fused_mark_around_the_reference(tmp_path):
    """Eq. 13 acts on the fused mark (around the nominal target here), not on each mark against the earlier ones."""
    src = _Recorder(answers=[OBJ + [0.3, 0.0, 0.022]])  # a wild first mark, 0.3 m off in x
    expert, _ = _pick_place(src, tmp_path)
    expert.begin_demonstration()
    target = _target_m(expert.action(scene_obs(1)).executed)
    ref = phase_target(1, OBJ, GOAL, TaskConfig())  # the nominal reference: the part's top centre
    assert (
        np.linalg.norm(target - ref) == pytest.approx(0.05, abs=1e-6) and target[0] > ref[0] + 0.049
    )  # on the 5 cm sphere
    assert expert.counts.projected == 1 and np.allclose(
        expert.fusion.offsets[PICK_PHASE][0], [0.3, 0.0, 0.022]
    )  # kept as marked


class _Recorder:
    """An expert source that answers like the oracle (plus an offset) and records the phases it was asked."""

    def __init__(self, offset=(0.0, 0.0, 0.0), answers=None):
        self.offset = np.asarray(offset, dtype=float)
        self.asked, self.previous = [], []
        self.answers = answers

    def annotate(self, obs, previous=None):
        self.asked.append(phase_from_progress(obs[4]))
        self.previous.append(previous)
        if self.answers is not None:
            target = self.answers.pop(0)
            return None if target is None else Annotation(np.array(target), 1.0, "live")
        target, grip = oracle_target(obs, TaskConfig())
        return Annotation(target + self.offset, grip, "live")


def _pick_place(source, tmp_path, reask_after=15, path="ann.jsonl"):
    task = TaskConfig()
    cache = AnnotationCache(0.005, tmp_path / path)
    expert = GuidedExpert(
        source,
        NominalReference(task),
        cache,
        0.05,
        task,
        load_robot().workspace.to_normalized,
        reask_after,
        marks="pick_place",
    )
    return expert, cache


def _target_m(action):
    return load_robot().workspace.to_cartesian(action[:3])


def test_a_pick_place_demonstration_asks_two_marks_and_follows_the_five_waypoints(tmp_path):
    src = _Recorder()
    expert, _ = _pick_place(src, tmp_path)
    expert.begin_demonstration()
    task = TaskConfig()
    resting = OBJ + [0.0, 0.0, 0.025 - GRASP_PRESS]  # where the cup rests when sealed (the mark: its lip pressed in)
    for phase in range(5):
        for _ in range(3):
            tcp = resting if phase == 2 else (0.5, 0.1, 0.3)
            step = expert.action(scene_obs(phase, tcp=tcp, g=1 if phase in (2, 3) else -1))
            expected = oracle_target(scene_obs(phase), task)[0]
            if phase == PLACE_PHASE:  # the release sets down a little below the place mark, opening where it stops
                expected = expected - [0.0, 0.0, RELEASE_DEPTH]
            assert np.allclose(_target_m(step.executed), expected, atol=1e-6), phase
    assert src.asked == [PICK_PHASE, PLACE_PHASE] and expert.counts.asked == 2 and expert.counts.reused == 13
    # the same start restored (a replayed demonstration) reuses both marks
    expert.begin_demonstration()
    for phase in range(5):
        expert.action(scene_obs(phase, tcp=resting if phase == 2 else (0.5, 0.1, 0.3)))
    assert expert.counts.asked == 2 and src.asked == [PICK_PHASE, PLACE_PHASE]
    # the grasp sealed (the demonstration went on to the lift): in another scene the pick is where it sealed, relative
    # to the part, and nobody is asked for it; the place is asked again (one mark of it is not yet settled)
    assert expert.counts.measured == 2 and len(expert.fusion.measured[PICK_PHASE]) == 2  # held through each lift
    expert.begin_demonstration()
    other, goal = OBJ + [0.05, 0.1, 0.0], GOAL + [0.0, 0.05, 0.0]
    step = expert.action(scene_obs(1, obj=other, goal=goal))
    assert expert.counts.asked == 2 and np.allclose(
        _target_m(step.executed), oracle_target(scene_obs(1, obj=other), task)[0], atol=1e-6
    )
    step = expert.action(scene_obs(4, obj=other, goal=goal, g=1))
    assert expert.counts.asked == 3 and src.asked[-1] == PLACE_PHASE


def test_pick_place_fuses_the_marks_of_a_run(tmp_path):
    """A biased, scattered person: every new demonstration uses the median offset of all marks so far."""
    scenes = [OBJ + [0.0, 0.1 * k, 0.0] for k in range(3)]
    errors = [[0.0, 0.0, 0.01], [0.02, 0.0, 0.01], [0.03, 0.0, 0.01]]
    src = _Recorder(answers=[obj + [0.0, 0.0, 0.022] + err for obj, err in zip(scenes, errors)])
    expert, _ = _pick_place(src, tmp_path)
    offsets = []
    for obj in scenes:
        expert.begin_demonstration()
        offsets.append(_target_m(expert.action(scene_obs(1, obj=obj)).executed) - obj)
    assert expert.counts.asked == 3
    assert np.allclose([o[0] for o in offsets], [0.0, 0.01, 0.02], atol=1e-6)  # medians of 0; 0, 2; 0, 2, 3 cm
    assert np.allclose([o[2] for o in offsets], 0.032, atol=1e-6)


def test_pick_place_remarks_an_unreached_place_and_resume_rebuilds_the_fusion(tmp_path):
    goal_top = GOAL + [0.0, 0.0, 0.025]
    src = _Recorder(answers=[goal_top + [0.0, 0.0, 0.04], goal_top])
    expert, _ = _pick_place(src, tmp_path, reask_after=15)
    expert.begin_demonstration()
    first = [_target_m(expert.action(scene_obs(4, g=1)).executed) for _ in range(15)]
    assert expert.counts.asked == 1 and expert.counts.remarks == 0
    again = _target_m(expert.action(scene_obs(4, g=1)).executed)
    assert expert.counts.remarks == 1 and expert.counts.asked == 2 and src.previous[1] is not None
    assert np.allclose(src.previous[1].target, goal_top + [0.0, 0.0, 0.04])
    down = goal_top[2] - RELEASE_DEPTH  # the release sets down a little below the fused mark
    assert np.allclose(first[0][2], down + 0.04) and np.allclose(again[2], down + 0.02)  # median of 4 and 0 cm
    # a resumed trainer reloads the file and rebuilds the same fused estimate
    resumed, fresh = _pick_place(_Recorder(answers=[]), tmp_path, path="ann.jsonl")
    fresh.load(tmp_path / "ann.jsonl")
    resumed.reload()
    assert np.allclose(resumed.fusion.estimate(PLACE_PHASE), expert.fusion.estimate(PLACE_PHASE))
    assert len(resumed.fusion.offsets[PLACE_PHASE]) == 2  # the superseded mark still counts as a measurement


def test_a_pick_mark_that_never_seals_is_searched_around_then_marked_again(tmp_path):
    """A pick mark 11 mm above the part's top: the grasp holds it, presses below it, then tries the grid around it,
    each probe first from above; every probe beyond the mark is counted, and with no seal the person marks again."""
    grasp = ws.PATTERNS[Phase.GRASP]
    src = _Recorder(offset=(0.0, 0.0, 0.011))
    expert, _ = _pick_place(src, tmp_path)
    expert.begin_demonstration()
    mark = oracle_target(scene_obs(1), TaskConfig())[0] + [0.0, 0.0, 0.011]
    per_probe = grasp.hover + grasp.press
    targets = [_target_m(expert.action(scene_obs(1)).executed) for _ in range(grasp.first_dwell + 2 * per_probe)]
    assert all(np.allclose(t, mark, atol=1e-6) for t in targets[: grasp.first_dwell])
    floor = load_robot().workspace.lo[2]
    pressed = targets[grasp.first_dwell + grasp.hover]
    assert np.allclose(pressed, [*mark[:2], max(mark[2] - grasp.depth, floor)], atol=1e-6)
    above_next = targets[grasp.first_dwell + per_probe]  # the next probe, first from above
    assert np.allclose(above_next, mark + [grasp.pitch, 0.0, grasp.clearance], atol=1e-6)
    assert expert.counts.probes == 2 and expert.counts.asked == 1
    for _ in range(grasp.first_dwell + len(grasp.grid) * per_probe - len(targets)):
        expert.action(scene_obs(1))
    assert expert.counts.asked == 1 and expert.counts.probes == len(grasp.grid)
    expert.action(scene_obs(1))  # every probe failed: the person marks again
    assert expert.counts.asked == 2 and expert.counts.remarks == 1 and src.previous[-1] is not None


def test_a_grasp_that_does_not_seal_at_the_mark_probes_where_the_cell_sees_the_part(tmp_path):
    """A pick mark 15 mm beside the part and 11 mm above it: after the dwell on it the search's first press is over
    the part's centre as the cell sees it (here without error), its next ones a pitch around that."""
    grasp = ws.PATTERNS[Phase.GRASP]
    expert, _ = _pick_place(_Recorder(offset=(0.015, 0.0, 0.011)), tmp_path)
    expert.begin_demonstration()
    per_probe = grasp.hover + grasp.press
    targets = [_target_m(expert.action(scene_obs(1)).executed) for _ in range(grasp.first_dwell + 2 * per_probe)]
    first, second = targets[grasp.first_dwell + grasp.hover], targets[grasp.first_dwell + per_probe + grasp.hover]
    assert np.allclose(first[:2], OBJ[:2], atol=1e-6)
    assert np.isclose(np.linalg.norm(second[:2] - OBJ[:2]), grasp.pitch)


def test_where_the_grasp_sealed_becomes_the_pick_of_later_demonstrations(tmp_path):
    grasp = ws.PATTERNS[Phase.GRASP]
    src = _Recorder(offset=(0.0, 0.0, 0.011))
    expert, _ = _pick_place(src, tmp_path)
    expert.begin_demonstration()
    for _ in range(grasp.first_dwell + grasp.hover + grasp.press):  # up to the pressed probe under the mark
        sealed_at = _target_m(expert.action(scene_obs(1)).executed)
    resting = OBJ + [0.0, 0.0, 0.026]  # the cup rests on the part's top, 1 mm above it
    expert.action(scene_obs(2, tcp=resting, g=1))  # the grasp completed: the lift
    assert expert.counts.measured == 0  # not yet: only a part held through the lift counts
    expert.action(scene_obs(3, tcp=resting + [0.0, 0.0, 0.1], g=1))
    assert expert.counts.measured == 1
    measured = expert.fusion.measured[PICK_PHASE][0]  # laterally the probe, in height as far as the cup came down
    assert np.allclose(measured, [*(sealed_at - OBJ)[:2], 0.026], atol=1e-6)
    expert.begin_demonstration()
    other = OBJ + [0.04, -0.03, 0.0]
    first = _target_m(expert.action(scene_obs(1, obj=other)).executed)
    assert np.allclose(first, other + measured, atol=1e-6) and expert.counts.asked == 2  # the place only


def test_a_measured_pick_whose_search_finds_nothing_is_withdrawn_and_the_marks_decide_again(tmp_path):
    """A pick measured 46 mm beside the part (a part the cup dragged before it sealed, measured where it had lain):
    the demonstrations plan their grasp there, the search around it finds nothing, and the measurement is withdrawn;
    the person's new mark and the earlier ones are the pick again, and the next demonstration plans from them."""
    grasp = ws.PATTERNS[Phase.GRASP]
    src = _Recorder()  # exact marks
    expert, _ = _pick_place(src, tmp_path)
    expert.begin_demonstration()
    exact = _target_m(expert.action(scene_obs(1)).executed)  # the first mark: the part's top centre
    expert.fusion.add_measurement(PICK_PHASE, OBJ, exact + [-0.046, 0.0, 0.0])
    expert.begin_demonstration()
    beside = _target_m(expert.action(scene_obs(1)).executed)
    assert np.allclose(beside, exact + [-0.046, 0.0, 0.0], atol=1e-6) and expert.counts.asked == 1  # not asked
    for _ in range(grasp.first_dwell + len(grasp.grid) * (grasp.hover + grasp.press) - 1):
        expert.action(scene_obs(1))
    assert len(expert.fusion.measured[PICK_PHASE]) == 1 and expert.counts.asked == 1
    after = _target_m(expert.action(scene_obs(1)).executed)  # every probe failed: withdrawn, the person marks again
    assert expert.fusion.measured[PICK_PHASE] == []
    assert expert.counts.asked == 2 and np.allclose(after, exact, atol=1e-6)
    expert.begin_demonstration()
    assert np.allclose(_target_m(expert.action(scene_obs(1)).executed), exact, atol=1e-6)


def test_withdrawing_drops_only_the_measurements_of_that_kind():
    fusion = MarkFusion()
    fusion.add(PICK_PHASE, OBJ, OBJ + [0.0, 0.0, 0.03])
    fusion.add_measurement(PICK_PHASE, OBJ, OBJ + [0.01, 0.0, 0.025])
    fusion.add_measurement(PLACE_PHASE, GOAL, GOAL + [0.0, 0.0, 0.03])
    assert fusion.settled(PICK_PHASE, 0.005) and fusion.withdraw(PICK_PHASE) == 1
    assert not fusion.settled(PICK_PHASE, 0.005)  # one mark: not known to 5 mm
    assert np.allclose(fusion.estimate(PICK_PHASE), [0.0, 0.0, 0.03])  # the marks again
    assert len(fusion.measured[PLACE_PHASE]) == 1 and fusion.withdraw(PICK_PHASE) == 0


def test_an_approach_completed_beside_the_mark_moves_the_grasp_there(tmp_path):
    """A pick mark 30 mm beside the part: the approach does not complete above it, the search completes it above the
    part, and the grasp goes down where the approach completed, not under the mark."""
    approach = ws.PATTERNS[Phase.APPROACH]
    src = _Recorder(offset=(0.03, 0.0, 0.0))
    expert, _ = _pick_place(src, tmp_path)
    expert.begin_demonstration()
    for _ in range(approach.first_dwell + 5 * approach.press):  # up to the grid's probe at -1 pitch in x
        target = _target_m(expert.action(scene_obs(0)).executed)
    assert np.allclose(target[0], OBJ[0] + 0.03 - approach.pitch, atol=1e-6)
    completed_at = OBJ + [0.03 - approach.pitch, 0.0, 0.108]
    grasp = _target_m(expert.action(scene_obs(1, tcp=completed_at)).executed)
    mark = oracle_target(scene_obs(1), TaskConfig())[0] + [0.03, 0.0, 0.0]
    assert np.allclose(grasp, mark - [approach.pitch, 0.0, 0.0], atol=1e-6)


def test_the_release_opens_where_the_part_came_to_rest_and_a_success_measures_the_place(tmp_path):
    """A place mark 3 cm below the table: the release descends towards it, and the vacuum opens where the descent
    stops (the part stands on the table); that point, measured once the episode succeeded, is the place from then on."""
    goal_top = GOAL + [0.0, 0.0, 0.025]
    src = _Recorder(answers=[OBJ + [0.0, 0.0, 0.022], goal_top - [0.0, 0.0, 0.03]])
    expert, _ = _pick_place(src, tmp_path)
    expert.begin_demonstration()
    expert.action(scene_obs(1))
    grips = [
        expert.action(scene_obs(4, tcp=goal_top + [0.0, 0.0, dz], g=1)).executed[3] for dz in (0.1, 0.05, 0.001, 0.0)
    ]
    assert grips == [1.0, 1.0, 1.0, -1.0]  # opened once the descent stopped, 3 cm above where it was sent
    expert.end_demonstration(success=True)
    assert np.allclose(expert.fusion.measured[PLACE_PHASE][0], [0.0, 0.0, 0.025], atol=1e-6)
    assert expert.fusion.settled(PLACE_PHASE, 0.0)


@pytest.mark.parametrize(("beside", "centred"), [(0.010, True), (0.004, False)])
def test_a_grasp_seen_hanging_off_the_cup_is_measured_over_the_parts_centre(tmp_path, beside, centred):
    """A pick mark 1 cm beside the part's centre that sealed as marked (the cell's cup reaches 5 mm, a looser one
    further): through the lift the cell sees the part hang 1 cm off the cup's axis, so the seal is measured over the
    part's centre, and the next demonstrations do not grasp at the edge where the policy's next wobble drops the part.
    Within CENTRED it is kept as it sealed."""
    from mrguide.policies.pick_place_demo import CENTRED

    assert beside > CENTRED if centred else beside < CENTRED
    grasp = ws.PATTERNS[Phase.GRASP]
    expert, _ = _pick_place(_Recorder(offset=(beside, 0.0, 0.0)), tmp_path)
    expert.begin_demonstration()
    for _ in range(grasp.first_dwell):
        sealed_at = _target_m(expert.action(scene_obs(1)).executed)
    assert np.isclose(sealed_at[0] - OBJ[0], beside)
    for dz in (0.0, 0.03, 0.06):  # the lift: the part rises with the cup, `beside` off its axis
        expert.action(scene_obs(2, obj=OBJ + [0.0, 0.0, dz], tcp=OBJ + [beside, 0.0, 0.026 + dz], g=1))
    expert.action(scene_obs(3, obj=OBJ + [0.0, 0.0, 0.1], tcp=OBJ + [beside, 0.0, 0.126], g=1))
    measured = expert.fusion.measured[PICK_PHASE][0]
    assert np.allclose(measured[:2], [0.0 if centred else beside, 0.0], atol=1e-6)


def test_a_success_beside_the_goal_measures_the_place_over_it(tmp_path):
    """A place mark 1.8 cm beside the goal succeeds (within ε): the success measures the height where the part met
    the table, over the goal, so the next demonstrations do not keep the place at the edge of ε."""
    goal_top = GOAL + [0.0, 0.0, 0.025]
    beside = np.array([0.018, -0.004, 0.0])
    src = _Recorder(answers=[OBJ + [0.0, 0.0, 0.022], goal_top + beside])
    expert, _ = _pick_place(src, tmp_path)
    expert.begin_demonstration()
    expert.action(scene_obs(1))
    for dz in (0.1, 0.0):
        expert.action(scene_obs(4, tcp=goal_top + beside + [0.0, 0.0, dz], g=1))
    expert.end_demonstration(success=False)
    assert expert.fusion.measured[PLACE_PHASE] == []  # a failure measures nothing
    expert.end_demonstration(success=True)
    assert np.allclose(expert.fusion.measured[PLACE_PHASE][0], [0.0, 0.0, 0.025], atol=1e-6)


def test_settled_marks_are_not_asked_again(tmp_path):
    """Exact place marks: after MIN_MARKS their median cannot move, and a new scene's place uses it unasked; a
    scattered person is asked until the median's standard error is within the precision."""
    from mrguide.policies.mark_fusion import MIN_MARKS

    fusion = MarkFusion()
    for _ in range(MIN_MARKS):
        assert not fusion.settled(PLACE_PHASE, 0.005)
        fusion.add(PLACE_PHASE, GOAL, GOAL + [0.0, 0.0, 0.025])
    assert fusion.settled(PLACE_PHASE, 0.0)
    rng = np.random.default_rng(0)
    scattered, n = MarkFusion(), 0
    while not scattered.settled(PLACE_PHASE, 0.005):
        scattered.add(PLACE_PHASE, GOAL, GOAL + rng.normal(0.0, 0.015, 3))
        n += 1
    assert 12 <= n <= 40  # (1.25 · 15 mm / 5 mm)² ≈ 14 marks for a 1.5 cm scatter
    assert np.all(np.abs(scattered.estimate(PLACE_PHASE)) < 0.015)


def test_pick_place_nobody_answering_ends_the_demonstration(tmp_path):
    expert, cache = _pick_place(_Recorder(answers=[None]), tmp_path)
    expert.begin_demonstration()
    assert expert.action(scene_obs(0)) is None and expert.counts.asked == 1 and len(cache) == 0


def test_a_short_guided_run_asks_two_marks_and_then_uses_what_the_cell_measured(tmp_path):
    import dataclasses

    from mrguide.policies.train import Trainer
    from tests.run_configs import run_config, sections

    tc, dc, gc, ec = sections()
    tc = dataclasses.replace(tc, total_steps=600, eval_every=10_000, checkpoint_every=10_000)
    gc = dataclasses.replace(gc, marks="pick_place", source="oracle")
    tr = Trainer(run_config(tc, dc, gc, ec), tmp_path)
    try:
        tr.run()
    finally:
        tr.close()
    demos = tr.counters.interventions
    assert demos > 3 and tr.counters.measured >= demos  # exact marks: every demonstration sealed and placed
    assert tr.counters.asked == 2  # then nobody is asked: the cell measured the pick and the place
