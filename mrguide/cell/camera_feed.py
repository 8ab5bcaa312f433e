"""The twin as a camera: images of the marked object rendered by PyBullet, for the `camera` pose source.

`TwinCameraFeed` is a `FrameSource` (what `cv2.VideoCapture` is on the robot) whose frames come from a
process of its own, as the HMD's do (`hmd_stream`): rendering a 1280x720 frame takes ~0.1 s and PyBullet
holds the GIL, which would stall the 4 ms control loop in-process. That process has the table, the marked
cube and the arm, which mirror the true object pose and joints of the twin playing the robot, so the arm
hides the marker when it is between the camera and the object. The camera sits where the calibration file says it is and has its
intrinsics (no lens distortion: the renderer has none), so a dry run tests the camera code path with a
perfect registration.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np
import pybullet as pb

from mrguide.calibration.camera_model import CameraModel
from mrguide.cell.rendering import RENDER_NICENESS, marked_object_scene, stop_render_process
from mrguide.deploy.camera import CameraPoseSource, CameraSourceConfig, CameraStats, load_marker_pipeline
from mrguide.deploy.frames import Frame
from mrguide.twin.camera import Camera, Intrinsics
from mrguide.twin.visual_arm import ArmDrawing, VisualArm

#: How long a dry run waits for the camera to see the object after it was placed (s).
PLACED_TIMEOUT_S = 30.0
#: How long the render process may take to start (s).
START_TIMEOUT_S = 120.0


def _pinhole(camera: CameraModel) -> Intrinsics:
    return Intrinsics(camera.width, camera.height, camera.fx, camera.fy, camera.cx, camera.cy)


def render_marked_object(
    T_base_cam: np.ndarray,
    camera: CameraModel,
    poses: Sequence[tuple],
    object_size: float,
    dictionary: str,
    marker_id: int,
    marker_size_m: float,
) -> list[np.ndarray]:
    """RGB images of the marked cube at each (position, quaternion xyzw), seen from `T_base_cam`."""
    client = pb.connect(pb.DIRECT)
    try:
        cube, marker = marked_object_scene(client, object_size, dictionary, marker_id, marker_size_m)
        cam = Camera(client, T_base_cam, _pinhole(camera))
        images = []
        for pos, orn in poses:
            pb.resetBasePositionAndOrientation(cube, list(pos), list(orn), physicsClientId=client)
            marker.update()
            images.append(cam.render())
        return images
    finally:
        pb.disconnect(client)


def _feed_worker(
    conn,
    T_base_cam: np.ndarray,
    camera: dict,
    object_size: float,
    dictionary: str,
    marker_id: int,
    marker_size_m: float,
    arm: ArmDrawing,
) -> None:
    """Runs in the render process: answer each (object pose, joints) with the camera's image of the cell."""
    os.nice(RENDER_NICENESS)
    try:
        client = pb.connect(pb.DIRECT)
        cube, marker = marked_object_scene(client, object_size, dictionary, marker_id, marker_size_m)
        drawn = VisualArm(client, arm)
        cam = Camera(client, T_base_cam, _pinhole(CameraModel(**{**camera, "dist": tuple(camera["dist"])})))
        conn.send(("ready", None))
    except Exception as exc:  # report start-up failures to the parent instead of dying silently
        conn.send(("error", f"{type(exc).__name__}: {exc}"))
        return
    while (msg := conn.recv()) is not None:
        pos, orn, q = msg
        pb.resetBasePositionAndOrientation(cube, pos, orn, physicsClientId=client)
        marker.update()
        drawn.set(q)
        conn.send(cam.render())


class TwinCameraFeed:
    """A `FrameSource` whose frames are rendered in a process of its own from the twin's object pose and joints.

    The process starts here, before the simulated cell runs (starting it beside a running control loop stalled
    the loop); `view` (`TwinPlant.view` of the twin playing the robot) is set when there is one."""

    def __init__(
        self,
        T_base_cam: np.ndarray,
        camera: CameraModel,
        object_size: float,
        dictionary: str,
        marker_id: int,
        marker_size_m: float,
        arm: ArmDrawing,
    ):
        self.view: Callable[[], tuple[np.ndarray, np.ndarray, np.ndarray]] | None = None
        ctx = mp.get_context("spawn")
        self._conn, child = ctx.Pipe()
        self._proc = ctx.Process(
            target=_feed_worker,
            name="twin-camera",
            daemon=True,
            args=(
                child,
                np.asarray(T_base_cam, dtype=float),
                camera.to_dict(),
                object_size,
                dictionary,
                marker_id,
                marker_size_m,
                arm,
            ),
        )
        self._proc.start()
        end = time.monotonic() + START_TIMEOUT_S
        while not self._conn.poll(0.1):
            if not self._proc.is_alive() or time.monotonic() > end:
                self.close()
                raise RuntimeError("the twin camera's render process did not start")
        kind, info = self._conn.recv()
        if kind != "ready":
            self.close()
            raise RuntimeError(f"the twin camera's render process failed to start: {info}")

    def read(self) -> Frame | None:
        """The image of the cell as it is now, stamped when its state was read; None once the twin or the render
        process is gone."""
        t = time.monotonic()
        try:
            pos, orn, q = self.view()  # type: ignore[misc]
            self._conn.send((np.asarray(pos).tolist(), np.asarray(orn).tolist(), np.asarray(q).tolist()))
            return Frame(self._conn.recv(), t)
        except Exception:  # the twin closed under us (end of the run) or the process died: no more frames
            return None

    def close(self) -> None:
        stop_render_process(self._conn, self._proc)


class TwinCameraPoses:
    """The `camera` pose source of a dry run: `__call__` is dry_run's pose_factory, `refresh` its on_placed."""

    def __init__(self, cfg: CameraSourceConfig, base_dir: Path, object_size: float, arm: ArmDrawing):
        self.cfg = cfg
        self.pipeline = p = load_marker_pipeline(cfg, base_dir)  # bad files refused before the cell starts
        self.feed = TwinCameraFeed(
            p.T_base_hmd, p.camera, object_size, p.detector.cfg.dictionary, p.marker_id, p.detector.marker_size_m, arm
        )
        self.sources: list[CameraPoseSource] = []

    def __call__(self, cell) -> CameraPoseSource:
        if self.sources:
            raise RuntimeError("TwinCameraPoses serves one simulated cell")
        self.feed.view = cell.plant.view
        self.sources.append(CameraPoseSource(self.feed, self.pipeline, self.cfg.max_pose_age_s))
        return self.sources[0]

    def refresh(self) -> None:
        """The object was just placed: wait for a pose captured after that (PoseUnavailable if none comes)."""
        t = time.monotonic()
        for s in self.sources:
            s.wait_for_pose(after=t, timeout=PLACED_TIMEOUT_S)

    def stats(self) -> CameraStats | None:
        """The statistics of the (one) camera source of the run, if it started."""
        return self.sources[-1].stats() if self.sources else None

    def close(self) -> None:
        for s in self.sources:
            s.close()
        self.feed.close()
