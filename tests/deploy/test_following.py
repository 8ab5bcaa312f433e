"""The following-error monitor: the distance of each joint to its nearest recent setpoint, computed in the control
thread without a NumPy call long enough to let go of the GIL."""

from __future__ import annotations

import numpy as np
import pytest

from mrguide.deploy import following
from mrguide.deploy.following import GIL_SAFE_ELEMENTS, FollowingMonitor
from mrguide.drivers.cobot_state import CycleSample


def _sample(cycle: int, setpoint: np.ndarray | None, positions: np.ndarray) -> CycleSample:
    return CycleSample(cycle, 0.0, setpoint, positions, np.full(len(positions), cycle))


def _reference(history: np.ndarray, positions: np.ndarray) -> tuple[int, float]:
    """The nearest-setpoint distance per joint over the whole history, worked out in one piece."""
    per_joint = np.abs(history - positions).min(axis=0)
    return int(per_joint.argmax()), float(per_joint.max())


@pytest.mark.parametrize("depth", [25, 250, 1200])
def test_the_error_is_the_distance_to_the_nearest_setpoint_of_the_window(depth: int) -> None:
    rng = np.random.default_rng(depth)
    monitor = FollowingMonitor(depth)
    setpoints = np.cumsum(rng.normal(0.0, 0.01, (3 * depth, 6)), axis=0)
    for k, q in enumerate(setpoints):
        positions = q + rng.normal(0.0, 0.02, 6)
        monitor(_sample(k, q, positions))
        joint, error = _reference(setpoints[max(0, k + 1 - depth) : k + 1], positions)
        assert (monitor.joint, monitor.error) == (joint, pytest.approx(error, abs=1e-15))


def test_a_position_that_is_not_a_number_is_the_worst_error() -> None:
    monitor = FollowingMonitor(25)
    monitor(_sample(0, np.zeros(6), np.zeros(6)))
    monitor(_sample(1, None, np.array([0.0, 0.3, np.nan, 0.0, 0.0, 0.0])))
    assert monitor.joint == 2 and np.isnan(monitor.error)


def test_without_setpoints_there_is_no_error() -> None:
    monitor = FollowingMonitor(25)
    monitor(_sample(0, None, np.ones(6)))
    assert (monitor.joint, monitor.error) == (0, 0.0)


class _RecordingNumpy:
    """numpy, with the size of every array handed to a ufunc the monitor calls recorded."""

    def __init__(self) -> None:
        self.sizes: list[int] = []

    def __getattr__(self, name: str):
        attr = getattr(np, name)
        if not isinstance(attr, np.ufunc):
            return attr

        def call(*args, **kwargs):
            self.sizes += [np.size(a) for a in args if isinstance(a, np.ndarray)]
            return attr(*args, **kwargs)

        return call


def test_no_numpy_call_of_a_cycle_is_long_enough_to_release_the_gil(monkeypatch: pytest.MonkeyPatch) -> None:
    """NumPy releases the GIL around a ufunc loop over more than 500 elements; in the control thread that lets
    another thread hold the cycle up to the 5 ms switch interval. A 1 s window at 1 ms is 1,000 setpoints."""
    recording = _RecordingNumpy()
    monitor = FollowingMonitor(1000)
    monkeypatch.setattr(following, "np", recording)
    for k in range(1500):
        monitor(_sample(k, np.full(6, 1e-3 * k), np.full(6, 1e-3 * k - 0.01)))
    assert recording.sizes and max(recording.sizes) <= GIL_SAFE_ELEMENTS
    assert monitor.error == pytest.approx(0.0, abs=1e-12)  # a 10 ms lag is a setpoint of the window
