"""The `camera` pose source on twin-rendered images with known ground truth: positions, timestamps and age,
failing cameras, and bad files."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from mrguide.calibration.errors import CalibrationFileError
from mrguide.deploy.camera import (
    MAX_GRAB_FAILURES,
    CameraPoseSource,
    CameraSourceConfig,
    load_marker_pipeline,
    open_camera_source,
)
from mrguide.deploy.frames import CameraError, Frame, FrameGrabError, ReplayFrames, folder_frames, open_frames
from mrguide.pose_source import PoseUnavailable


def _config(scene, **changes) -> CameraSourceConfig:
    return CameraSourceConfig(
        **{"source": str(scene.folder), "calibration": str(scene.calibration), "frame_rate": 0.0, **changes}
    )


def test_folder_replay_gives_robot_frame_positions_within_2_mm(camera_scene, tmp_path):
    seen, done = [], threading.Event()

    def on_frame(frame, observation):
        seen.append(observation.position)
        if len(seen) == len(camera_scene.truths):
            done.set()

    source = open_camera_source(_config(camera_scene), tmp_path, on_frame)
    try:
        assert done.wait(60), f"only {len(seen)} frames processed"
    finally:
        source.close()
    errors_mm = [np.linalg.norm(p - t) * 1e3 for p, t in zip(seen, camera_scene.truths)]
    assert max(errors_mm) < 2.0, errors_mm
    stats = source.stats()
    assert stats.frames == 3 and stats.poses == 3 and stats.detection_rate == 1.0
    assert stats.lost == "the camera source has no more frames"  # a folder replays once by default
    assert 0 < stats.latency_median_ms < 5000


class FakeClock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def test_pose_carries_its_capture_time_and_goes_stale_after_max_age(camera_scene, tmp_path):
    clock = FakeClock()
    image = folder_frames(camera_scene.folder, 0.0).load(0)
    pipeline = load_marker_pipeline(_config(camera_scene), tmp_path)
    source = CameraPoseSource(ReplayFrames(1, lambda k: image, 0.0, clock=clock), pipeline, 0.5, clock=clock)
    try:
        pose = source.wait_for_pose(after=0.0, timeout=30)
    finally:
        source.close()
    assert pose.t_capture == 100.0
    clock.t = 100.4
    assert np.linalg.norm(source.object_position() - camera_scene.truths[0]) < 0.002
    clock.t = 100.6
    with pytest.raises(PoseUnavailable, match=r"0.60 s old \(max_pose_age_s 0.5\).*no more frames"):
        source.object_position()


def test_no_marker_in_view_means_no_pose(camera_scene, tmp_path):
    blank = np.full((720, 1280, 3), 200, np.uint8)
    source = CameraPoseSource(
        ReplayFrames(2, lambda k: blank, 0.0), load_marker_pipeline(_config(camera_scene), tmp_path), 1.0
    )
    with pytest.raises(PoseUnavailable, match="no more frames"):
        source.wait_for_pose(after=0.0, timeout=30)
    source.close()
    with pytest.raises(PoseUnavailable, match="has not seen marker 0 yet"):
        source.object_position()
    assert source.stats().frames == 2 and source.stats().detection_rate == 0.0


class BrokenCamera:
    """A device whose every grab fails."""

    def __init__(self) -> None:
        self.grabs = 0

    def read(self) -> Frame:
        self.grabs += 1
        raise FrameGrabError("frame grab failed")

    def close(self) -> None:
        pass


def test_failing_grabs_stop_the_source_with_a_reason(camera_scene, tmp_path):
    camera = BrokenCamera()
    source = CameraPoseSource(camera, load_marker_pipeline(_config(camera_scene), tmp_path), 1.0)
    source._thread.join(10)
    source.close()
    assert camera.grabs == MAX_GRAB_FAILURES
    with pytest.raises(PoseUnavailable, match=f"{MAX_GRAB_FAILURES} frame grabs failed in a row"):
        source.object_position()


def test_image_of_the_wrong_size_is_a_bad_input(camera_scene, tmp_path):
    small = np.zeros((480, 640, 3), np.uint8)
    source = CameraPoseSource(
        ReplayFrames(1, lambda k: small, 0.0), load_marker_pipeline(_config(camera_scene), tmp_path), 1.0
    )
    source._thread.join(10)
    source.close()
    assert source.error is not None and "image is 640x480 but the intrinsics are for 1280x720" in str(source.error)


def test_unreadable_image_in_a_folder_is_skipped_and_counted(camera_scene, tmp_path):
    folder = tmp_path / "images"
    folder.mkdir()
    (folder / "a.png").write_bytes((camera_scene.folder / "frame00.png").read_bytes())
    (folder / "b.png").write_text("not an image")
    source = open_camera_source(_config(camera_scene, source=str(folder)), tmp_path)
    source._thread.join(30)
    source.close()
    stats = source.stats()
    assert (stats.frames, stats.poses, stats.grab_failures) == (1, 1, 1)


@pytest.mark.parametrize(
    "source, words",
    [
        (57, ["camera source 57", "cannot open this device"]),
        ("rtsp://127.0.0.1:9/none", ["rtsp://127.0.0.1:9/none", "cannot open this stream"]),
        ("missing", ["camera source 'missing'", "no such folder or file"]),
        ("empty", ["the folder holds no images"]),
    ],
)
def test_a_camera_that_cannot_be_opened_is_an_input_error(tmp_path, source, words):
    (tmp_path / "empty").mkdir()
    with pytest.raises(CameraError) as info:
        open_frames(source, tmp_path, 10.0, False)
    for word in words:
        assert word in str(info.value)


def test_missing_or_corrupt_calibration_is_an_input_error(camera_scene, tmp_path):
    with pytest.raises(CalibrationFileError, match="calibration file not found"):
        load_marker_pipeline(_config(camera_scene, calibration="nope.json"), tmp_path)
    (tmp_path / "bad.json").write_text("{")
    with pytest.raises(CalibrationFileError, match="not valid JSON"):
        load_marker_pipeline(_config(camera_scene, calibration="bad.json"), tmp_path)
