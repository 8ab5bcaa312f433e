"""Ruckig streaming respects every limit of the robot spec."""

import numpy as np
import pytest

from mrguide.motion.trajectory import JointStreamer, TrajectoryError
from mrguide.robot import load_robot


def test_stream_respects_limits_and_reaches_targets():
    spec = load_robot()
    dt = 0.004
    s = JointStreamer(spec, dt)
    rng = np.random.default_rng(0)
    prev_q, _, prev_ddq = s.state()
    for k in range(8):
        target = rng.uniform(spec.q_lower + 0.1, spec.q_upper - 0.1)
        s.set_target(target)
        # retarget mid-motion half of the time
        n_cycles = 5000 if k % 2 == 0 else 60
        for _ in range(n_cycles):
            sp = s.step()
            assert spec.within_limits(sp.q)
            assert np.all(np.abs(sp.dq) <= spec.v_max * (1 + 1e-6) + 1e-9)
            assert np.all(np.abs(sp.ddq) <= spec.a_max * (1 + 1e-6) + 1e-9)
            jerk = (sp.ddq - prev_ddq) / dt
            assert np.all(np.abs(jerk) <= spec.j_max * (1 + 1e-3) + 1e-6)
            # position is consistent with the velocity it reports
            assert np.all(np.abs(sp.q - prev_q) <= spec.v_max * dt * (1 + 1e-6) + 1e-9)
            prev_q, prev_ddq = sp.q, sp.ddq
            if sp.finished:
                break
        if k % 2 == 0:
            assert sp.finished
            assert np.allclose(sp.q, target, atol=1e-6)


def test_target_outside_limits_is_refused():
    spec = load_robot()
    s = JointStreamer(spec)
    bad = spec.q_upper + 0.1
    with pytest.raises(TrajectoryError, match="outside the joint limits"):
        s.set_target(bad)
    with pytest.raises(TrajectoryError, match="finite"):
        s.set_target(np.full(spec.dof, np.nan))


def test_brake_stops_within_limits_without_returning():
    spec = load_robot()
    dt = 0.004
    s = JointStreamer(spec, dt)
    s.set_target(spec.q_home + 0.8 * np.sign(spec.q_upper - spec.q_home - 0.8))
    for _ in range(60):
        sp = s.step()
    assert np.max(np.abs(sp.dq)) > 0.5  # moving fast
    s.brake()
    prev = sp
    for _ in range(500):
        sp = s.step()
        assert np.all(np.abs(sp.ddq) <= spec.a_max * (1 + 1e-6) + 1e-9)
        assert np.all(np.abs(sp.ddq - prev.ddq) / dt <= spec.j_max * (1 + 1e-3) + 1e-6)
        # no joint reverses direction while braking
        assert np.all(sp.dq * prev.dq >= -1e-9)
        prev = sp
    assert np.allclose(sp.dq, 0.0, atol=1e-9)


def test_ruckig_edge_case_from_rest_is_planned():
    """Ruckig 0.19 throws on a move that lies exactly on a boundary between its profile types (0.12 rad from rest
    at 1.5 rad/s, 6 rad/s^2, 60 rad/s^3: the dry run's start layouts are such offsets). It is retried, and the
    arm arrives within the limits."""
    spec = load_robot()
    streamer = JointStreamer(spec)
    start = spec.q_home + np.array([-0.12, 0.11037556, 0.12, -0.16, 0.0, -0.16])
    start[0] = -0.1200000000000001
    streamer.reset(start)
    streamer.set_target(spec.q_home)
    for _ in range(2000):
        sp = streamer.step()
        assert np.all(np.abs(sp.dq) <= spec.v_max + 1e-9)
        if sp.finished:
            break
    np.testing.assert_allclose(sp.q, spec.q_home, atol=1e-9)


def test_a_joint_at_rest_on_its_target_but_for_float_residue_is_planned():
    """The state a CI run's dry run stopped on ("error in step 2"): the arm on its target but for 1e-16 rad and
    2e-16 rad/s left by the last plan. The retry puts it at rest there."""
    spec = load_robot()
    streamer = JointStreamer(spec)
    target = np.array(
        [
            -0.5229453910300563,
            -1.456909805822409,
            2.248614502407839,
            -2.362501218453161,
            -1.5707963219737,
            -0.5229453921,
        ]
    )
    current = target + np.array([-1.1e-16, 0.0, 0.0, -4.4e-16, 0.0, 0.0])
    streamer.reset(
        current, np.array([0.0, 5.551115123125783e-17, 2.220446049250313e-16, -2.775557561562891e-17, 0.0, 0.0])
    )
    streamer.set_target(target)
    sp = streamer.step()
    assert sp.finished
    np.testing.assert_allclose(sp.q, target, atol=1e-12)
    assert np.all(sp.dq == 0.0)


def test_a_plan_ruckig_refuses_raises_trajectory_error():
    spec = load_robot()
    streamer = JointStreamer(spec)
    streamer.reset(spec.q_home)
    streamer.set_target(spec.q_home + 0.1)
    streamer._inp.max_jerk = [float("nan")] * spec.dof  # what no retry can plan
    with pytest.raises(TrajectoryError, match="Ruckig"):
        streamer.step()


def test_a_slowed_move_keeps_to_its_share_of_the_limits_and_the_next_has_them_all_again():
    spec = load_robot()
    s = JointStreamer(spec, 0.004)
    far = spec.q_home + np.array([0.8, -0.4, 0.5, 0.6, 0.4, 0.9])

    def peak(target):
        s.set_target(target)
        dq, ddq = [], []
        while not (sp := s.step()).finished:
            dq.append(np.abs(sp.dq) / spec.v_max)
            ddq.append(np.abs(sp.ddq) / spec.a_max)
        return np.max(dq), np.max(ddq)

    with s.slowed(0.25):
        v, a = peak(far)
    assert v <= 0.25 + 1e-6 and a <= 0.25 + 1e-6 and v > 0.2  # the move used its share, no more
    v, a = peak(spec.q_home)
    assert v > 0.9  # the limits are the arm's again after the block
    with pytest.raises(ValueError), s.slowed(0.0):
        pass
