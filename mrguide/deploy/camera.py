"""The `camera` object-pose source: a capture thread reads frames, finds the object's ArUco marker, estimates its
pose with the camera intrinsics and maps it into the robot frame with the registration from `mrguide calibrate`.

The per-frame work is the HMD's marker pipeline (`MarkerPoseSource.observe`) with the camera as the registered
frame (T_hmd_cam = I, as `mrguide calibrate --images` without `--poses` registers a fixed camera). Every pose
carries its capture time; `object_position()` refuses a pose older than `max_pose_age_s`. Nothing that goes
wrong in the thread escapes it: the reason is kept and reported through PoseUnavailable, so the runtime
decides (last pose for `max_pose_misses` decisions, then `pose_lost`). No PyBullet, no torch.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated

import numpy as np

from mrguide.calibration.calibration_file import load_calibration
from mrguide.calibration.camera_model import camera_from_dict, load_camera_model
from mrguide.calibration.config import DetectorConfig
from mrguide.calibration.detection import MarkerDetector
from mrguide.calibration.errors import CalibrationFileError
from mrguide.calibration.hmd import HmdFrame
from mrguide.calibration.pose_sources import MarkerObservation, MarkerPoseSource
from mrguide.config import ConfigError, Range, check_number, check_ranges
from mrguide.deploy.frames import Frame, FrameGrabError, FrameSource, open_frames
from mrguide.errors import InputError
from mrguide.pose_source import ObjectPoseSource, PoseUnavailable

log = logging.getLogger(__name__)

#: Failed grabs in a row after which the camera counts as gone.
MAX_GRAB_FAILURES = 25
#: Capture-to-pose latencies kept for the statistics.
LATENCY_WINDOW = 10_000
_IDENTITY = np.eye(4)


@dataclass(frozen=True)
class CameraSourceConfig:
    """`[deploy.camera]`: the camera that sees the object's marker (used with `[deploy] pose_source = "camera"`)."""

    source: int | str = 0  # device index, stream URL ("rtsp://..."), or a folder of images / a video file
    calibration: str = ""  # `mrguide calibrate` file of this camera (robot <- camera registration, intrinsics)
    intrinsics: str = ""  # intrinsics file; "" = the calibration file's "camera"
    marker_id: Annotated[int, Range(0, 999)] = 0  # the object's marker (dictionary: the calibration file's)
    marker_size_m: Annotated[float, Range(1e-3, 1.0, " m")] = 0.04  # its black-square edge
    #: From the marker centre to the object centre, in the marker frame (z out of the print): a 4 cm marker on
    #: top of the 5 cm cube sits 25.5 mm above its centre.
    marker_to_object_m: tuple[float, float, float] = (0.0, 0.0, -0.0255)
    max_pose_age_s: Annotated[float, Range(0.01, 60.0, " s")] = 1.0  # an older pose counts as missing
    #: folders: images per second (0 = as fast as they are processed)
    frame_rate: Annotated[float, Range(0.0, 1000.0, " Hz")] = 15.0
    loop: bool = False  # folders: start again after the last image

    def __post_init__(self) -> None:
        if isinstance(self.source, bool) or (isinstance(self.source, int) and not 0 <= self.source <= 1000):
            raise ConfigError(
                f"deploy.camera.source = {self.source!r}: expected a device index in [0, 1000], "
                "a stream URL, or a folder of images"
            )
        if isinstance(self.source, str) and not self.source.strip():
            raise ConfigError("deploy.camera.source must not be empty")
        check_ranges(self, "deploy.camera")
        for k, v in enumerate(self.marker_to_object_m):
            check_number(f"deploy.camera.marker_to_object_m[{k}]", v, -1.0, 1.0, " m")


def load_marker_pipeline(cfg: CameraSourceConfig, base_dir: Path) -> MarkerPoseSource:
    """The per-frame pipeline from the calibration (and intrinsics) file, relative to `base_dir`, warmed up."""
    if not cfg.calibration:
        raise ConfigError('deploy.camera.calibration: pose_source = "camera" needs the camera\'s calibration file')
    path = base_dir / cfg.calibration
    record = load_calibration(path)
    if cfg.intrinsics:
        camera = load_camera_model(base_dir / cfg.intrinsics)
    elif record.camera is not None:
        camera = camera_from_dict(record.camera, f"{path}: 'camera'")
    else:
        raise CalibrationFileError(f"{path}: holds no camera intrinsics; set deploy.camera.intrinsics")
    detector = MarkerDetector(DetectorConfig(dictionary=record.dictionary, marker_size_m=cfg.marker_size_m))
    # OpenCV's one-time set-up (thread pool, ~0.3 s on the first frame) now, not beside a running control loop
    detector.detect(np.zeros((camera.height, camera.width), np.uint8))
    return MarkerPoseSource(None, detector, camera, record.T_base_hmd, cfg.marker_id, cfg.marker_to_object_m)


@dataclass(frozen=True)
class TimedPose:
    """An object position (base frame, m) and the capture time of the frame it came from (monotonic, s)."""

    position: np.ndarray
    t_capture: float


@dataclass(frozen=True)
class CameraStats:
    """What the source did so far."""

    frames: int  # frames processed
    poses: int  # frames that gave an object position
    grab_failures: int
    poses_per_s: float
    latency_median_ms: float  # capture -> pose (nan before the first pose)
    latency_p95_ms: float
    lost: str | None  # why the capture thread stopped, if it did

    @property
    def detection_rate(self) -> float:
        return self.poses / self.frames if self.frames else 0.0

    def as_dict(self) -> dict:
        return {
            "frames": self.frames,
            "poses": self.poses,
            "detection_rate": self.detection_rate,
            "grab_failures": self.grab_failures,
            "poses_per_s": self.poses_per_s,
            "latency_median_ms": self.latency_median_ms,
            "latency_p95_ms": self.latency_p95_ms,
            "lost": self.lost,
        }

    def text(self) -> str:
        line = (
            f"camera: {self.frames} frames, {self.poses} poses ({self.detection_rate:.0%} detected), "
            f"{self.poses_per_s:.1f} poses/s, capture->pose latency median {self.latency_median_ms:.0f} ms, "
            f"p95 {self.latency_p95_ms:.0f} ms, failed grabs {self.grab_failures}"
        )
        return line + (f"; stopped: {self.lost}" if self.lost else "")


class CameraPoseSource(ObjectPoseSource):
    """The newest object pose from a capture thread over `frames` (started here; `close()` stops it)."""

    def __init__(
        self,
        frames: FrameSource,
        pipeline: MarkerPoseSource,
        max_pose_age_s: float,
        clock: Callable[[], float] = time.monotonic,
        on_frame: Callable[[Frame, MarkerObservation], None] | None = None,
    ):
        self.frames, self.pipeline, self.max_age, self.clock = frames, pipeline, max_pose_age_s, clock
        self.on_frame = on_frame  # called in the capture thread after each processed frame
        self._lock = threading.Lock()
        self._latest: TimedPose | None = None
        self._view: tuple[Frame, MarkerObservation] | None = None
        self._latency: deque[float] = deque(maxlen=LATENCY_WINDOW)
        self._frames = self._poses = self._failures = 0
        self._t_first: float | None = None
        self._lost: str | None = None
        self.error: InputError | None = None  # a bad input found in the thread (an image of the wrong size)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="camera-pose", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        failures = 0
        while not self._stop.is_set():
            try:
                frame = self.frames.read()
            except FrameGrabError as exc:
                failures += 1
                with self._lock:
                    self._failures += 1
                log.debug("%s", exc)
                if failures >= MAX_GRAB_FAILURES:
                    return self._lose(f"{failures} frame grabs failed in a row ({exc})")
                continue
            except Exception as exc:  # a device or feed that died: say why, never kill the run
                return self._lose(f"the camera failed ({type(exc).__name__}: {exc})")
            if frame is None:
                return self._lose("the camera source has no more frames")
            failures = 0
            try:
                self._process(frame)
            except InputError as exc:
                self.error = exc
                return self._lose(str(exc))

    def _process(self, frame: Frame) -> None:
        seen = self.pipeline.observe(HmdFrame(frame.image, _IDENTITY))
        t_done = self.clock()
        with self._lock:
            self._frames += 1
            self._view = (frame, seen)
            if self._t_first is None:
                self._t_first = frame.t_capture
            if seen.position is not None:
                self._poses += 1
                self._latest = TimedPose(seen.position, frame.t_capture)
                self._latency.append(t_done - frame.t_capture)
        if self.on_frame:
            self.on_frame(frame, seen)

    def _lose(self, reason: str) -> None:
        with self._lock:
            self._lost = reason
        log.warning("camera pose source stopped: %s", reason)

    def latest(self) -> TimedPose | None:
        """The newest pose with its capture time, however old."""
        with self._lock:
            return self._latest

    def object_position(self) -> np.ndarray:
        """The newest pose; PoseUnavailable when there is none or it is older than `max_pose_age_s`."""
        with self._lock:
            latest, lost = self._latest, self._lost
        why = f" ({lost})" if lost else ""
        if latest is None:
            raise PoseUnavailable(f"the camera has not seen marker {self.pipeline.marker_id} yet{why}")
        age = self.clock() - latest.t_capture
        if age > self.max_age:
            raise PoseUnavailable(f"the newest camera pose is {age:.2f} s old (max_pose_age_s {self.max_age}){why}")
        return latest.position.copy()

    def wait_for_pose(self, after: float, timeout: float) -> TimedPose:
        """The first pose captured after `after` (monotonic s); PoseUnavailable after `timeout` s or once the
        capture thread has stopped."""
        end = self.clock() + timeout
        while True:
            with self._lock:
                latest, lost = self._latest, self._lost
            if latest is not None and latest.t_capture > after:
                return latest
            if lost or self.clock() > end:
                raise PoseUnavailable(
                    f"no camera pose of marker {self.pipeline.marker_id} within {timeout} s"
                    + (f" ({lost})" if lost else "")
                )
            time.sleep(0.01)

    def running(self) -> bool:
        return self._thread.is_alive()

    def last_view(self) -> tuple[Frame, MarkerObservation] | None:
        """The newest processed frame and what it showed (for an overlay)."""
        with self._lock:
            return self._view

    def stats(self) -> CameraStats:
        with self._lock:
            lat = np.array(self._latency) * 1e3
            span = (self._latest.t_capture - self._t_first) if self._latest and self._t_first is not None else 0.0
            rate = (self._poses - 1) / span if span > 0 else 0.0
            return CameraStats(
                self._frames,
                self._poses,
                self._failures,
                rate,
                float(np.median(lat)) if len(lat) else float("nan"),
                float(np.percentile(lat, 95)) if len(lat) else float("nan"),
                self._lost,
            )

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)
        self.frames.close()


def open_camera_source(
    cfg: CameraSourceConfig, base_dir: Path, on_frame: Callable[[Frame, MarkerObservation], None] | None = None
) -> CameraPoseSource:
    """The configured camera, opened and capturing (files are checked before the device is opened)."""
    pipeline = load_marker_pipeline(cfg, base_dir)
    size = (pipeline.camera.width, pipeline.camera.height)
    return CameraPoseSource(
        open_frames(cfg.source, base_dir, cfg.frame_rate, cfg.loop, size),
        pipeline,
        cfg.max_pose_age_s,
        on_frame=on_frame,
    )
