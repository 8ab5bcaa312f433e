"""The HMD as a device of its own: a separate process that renders its camera, finds the object's marker
and reports the object position through its marker calibration, streamed to the deploy runtime.

Like a real HoloLens, it runs beside the robot controller, not inside its control loop: rendering a
1280x720 frame takes ~0.1 s and would stall the 4 ms CAN cycle if done in-process (PyBullet holds the
GIL). The HMD process has its own world with the table, the marked cube and the arm, which mirror the true
object pose and joints of the cell, so the arm hides the marker when it is in the line of sight: a PyBullet
world for the PyBullet cell (`ArmDrawing`), a MuJoCo model drawn by MuJoCo's offscreen renderer for the MuJoCo
cell (`MujocoDrawing`). At start-up the HMD is calibrated against the board exactly as `mrguide calibrate
--twin` does (PyBullet: before the arm is drawn; MuJoCo: with the arm at home, clear of the board).
"""

from __future__ import annotations

import logging
import math
import multiprocessing as mp
import multiprocessing.connection
import os
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from mrguide.cell.rendering import OFFSCREEN_GL_HELP, RENDER_NICENESS, stop_render_process
from mrguide.cell_layout import CupConfig
from mrguide.plant import CellView
from mrguide.pose_source import ObjectPoseSource, PoseUnavailable
from mrguide.robot import RobotSpec
from mrguide.twin.visual_arm import ArmDrawing

if TYPE_CHECKING:
    from mrguide.calibration.calibration_file import CalibrationRecord
    from mrguide.calibration.config import CalibrationConfig
    from mrguide.twin.markers import TwinCalibrationConfig

log = logging.getLogger(__name__)

#: Where the wearer stands and looks while the robot works (base frame, m): ~0.8 m from the object region.
WATCH_EYE = (1.0, -0.05, 0.55)
WATCH_TARGET = (0.50, -0.05, 0.0)
OBJECT_MARKER_ID = 0
#: Frames per second the HMD process is asked for at most. The runtime reads one pose per decision (10 Hz); a render
#: process drawing flat out (MuJoCo's draws faster than that) takes CPU the simulated cell's real-time threads need.
MAX_FRAME_RATE = 15.0


@dataclass(frozen=True)
class MujocoDrawing:
    """The MuJoCo cell as its HMD process draws it, with MuJoCo's own offscreen renderer (picklable)."""

    spec: RobotSpec
    cup: CupConfig


#: Poses the HMD process's scene as the cell is: part position, quaternion (x, y, z, w), arm joints.
ScenePoser = Callable[[ArrayLike, ArrayLike, ArrayLike], None]


def _hmd_worker(
    conn,
    calibration_path: str | None,
    object_size: float,
    noise_seed: int,
    hmd_overrides: dict,
    arm: ArmDrawing | MujocoDrawing,
) -> None:
    """Runs in the HMD process: calibrate, then answer each true (object pose, joints) with the HMD's estimate."""
    os.nice(RENDER_NICENESS)  # the simulated drives and the deploy loop share this machine: they go first

    from mrguide.calibration.config import load_calibration_config
    from mrguide.config import load_section
    from mrguide.twin.markers import TwinCalibrationConfig

    try:
        cfg = load_calibration_config(calibration_path)
        cfg = replace(cfg, hmd=replace(cfg.hmd, seed=noise_seed, **hmd_overrides))
        twin_cfg = (
            load_section(TwinCalibrationConfig, calibration_path, "calibration_twin")
            if calibration_path
            else TwinCalibrationConfig()
        )
        if isinstance(arm, MujocoDrawing):
            source, pose, quality = _mujoco_hmd(cfg, twin_cfg, object_size, arm)
        else:
            source, pose, quality = _pybullet_hmd(cfg, twin_cfg, object_size, arm)
        conn.send(("ready", quality))
    except Exception as exc:  # report start-up failures to the parent instead of dying silently
        conn.send(("error", f"{type(exc).__name__}: {exc}"))
        return
    _answer_poses(conn, pose, source)


def _pybullet_hmd(
    cfg: CalibrationConfig, twin_cfg: TwinCalibrationConfig, object_size: float, arm: ArmDrawing
) -> tuple[ObjectPoseSource, ScenePoser, dict]:
    """The HMD rendered by PyBullet: calibrated, looking at the cell; its pose source, poser and start-up report."""
    import pybullet as pb

    from mrguide.cell.rendering import marked_object_scene
    from mrguide.twin.camera import look_at
    from mrguide.twin.markers import TwinHmd, calibrate_twin_hmd, hmd_marker_pose_source
    from mrguide.twin.visual_arm import VisualArm

    client = pb.connect(pb.DIRECT)
    cube, marker = marked_object_scene(
        client, object_size, cfg.detector.dictionary, OBJECT_MARKER_ID, cfg.detector.marker_size_m
    )
    hmd = TwinHmd(
        client,
        twin_cfg.T_base_hmd,
        look_at(np.array(WATCH_EYE), np.array(WATCH_TARGET), np.array([0.0, 0.0, 1.0])),
        twin_cfg.intrinsics,
        twin_cfg.supersample,
        attached=[marker],
    )
    run = calibrate_twin_hmd(hmd, cfg, twin_cfg.views, twin_cfg.look_at, cfg.hmd)
    hmd.look_from(WATCH_EYE, WATCH_TARGET)
    hmd.supersample = 1  # streaming: ~4x faster frames than the calibration shots
    source = hmd_marker_pose_source(
        hmd, run.record.T_base_hmd, cfg.detector, OBJECT_MARKER_ID, -marker.T_body_marker[:3, 3], noise=cfg.hmd
    )
    drawn = VisualArm(client, arm)

    def pose(pos, orn, q) -> None:
        pb.resetBasePositionAndOrientation(cube, pos, orn, physicsClientId=client)
        drawn.set(np.asarray(q))

    return source, pose, _calibration_quality(run.record, twin_cfg.T_base_hmd)


def _mujoco_hmd(
    cfg: CalibrationConfig, twin_cfg: TwinCalibrationConfig, object_size: float, arm: MujocoDrawing
) -> tuple[ObjectPoseSource, ScenePoser, dict]:
    """The HMD of the MuJoCo cell rendered by MuJoCo offscreen (EGL unless MUJOCO_GL says otherwise)."""
    from mrguide.twin.markers import hmd_marker_pose_source

    try:
        from mrguide.cell.mujoco_hmd import MujocoHmd, calibrate_mujoco_hmd
    except Exception as exc:  # importing mujoco loads the OpenGL backend MUJOCO_GL names, and fails without it
        backend = os.environ.get("MUJOCO_GL")
        raise RuntimeError(f"mujoco cannot be imported with MUJOCO_GL={backend}: {exc}. {OFFSCREEN_GL_HELP}") from exc

    hmd = MujocoHmd(
        arm.spec,
        arm.cup,
        object_size,
        cfg,
        OBJECT_MARKER_ID,
        twin_cfg.T_base_hmd,
        twin_cfg.intrinsics,
        twin_cfg.supersample,
    )
    hmd.pose((*WATCH_TARGET[:2], 0.5 * object_size), (0.0, 0.0, 0.0, 1.0), arm.spec.q_home)
    run = calibrate_mujoco_hmd(hmd, cfg, twin_cfg.views, twin_cfg.look_at, cfg.hmd)
    hmd.look_from(WATCH_EYE, WATCH_TARGET)
    hmd.supersample = 1
    source = hmd_marker_pose_source(
        hmd, run.record.T_base_hmd, cfg.detector, OBJECT_MARKER_ID, -hmd.T_part_marker[:3, 3], noise=cfg.hmd
    )
    return source, hmd.pose, _calibration_quality(run.record, twin_cfg.T_base_hmd)


def _calibration_quality(record: CalibrationRecord, T_base_hmd_true: np.ndarray) -> dict:
    """The start-up report: the calibration's RMS residual and how far its HMD position is from the true one."""
    err = float(np.linalg.norm(record.T_base_hmd[:3, 3] - T_base_hmd_true[:3, 3]))
    return {"rms_residual_m": float(record.rms_residual_m), "T_base_hmd_translation_error_m": err}


def _answer_poses(conn: multiprocessing.connection.Connection, pose: ScenePoser, source: ObjectPoseSource) -> None:
    """Until None arrives: pose the scene as received, and send back the HMD's object estimate. A parent that is gone
    (killed: its end of the pipe closed) ends it quietly."""
    try:
        while (msg := conn.recv()) is not None:
            pose(*msg)
            try:
                answer: tuple[str, object] = ("pose", source.object_position())
            except PoseUnavailable as exc:
                answer = ("none", str(exc))
            conn.send(answer)
    except (EOFError, BrokenPipeError):
        return


def _start(proc: mp.process.BaseProcess, offscreen_gl: bool) -> None:
    """Start `proc`; with `offscreen_gl` its environment has MUJOCO_GL=egl (unless set) from its first import of
    mujoco on (the variable is read once, when mujoco is imported), while this process's is left as it was."""
    if not offscreen_gl or "MUJOCO_GL" in os.environ:
        proc.start()
        return
    os.environ["MUJOCO_GL"] = "egl"
    try:
        proc.start()
    finally:
        del os.environ["MUJOCO_GL"]


class HmdStartError(RuntimeError):
    """The HMD process could not start: it failed (e.g. its marker calibration did), died or stayed silent."""


class HmdPoseStream(ObjectPoseSource):
    """Latest object position from the HMD process; stale or missing estimates raise PoseUnavailable.

    `[calibration.hmd]` `latency_s`: an estimate is given only that long after its scene was seen (the render's own
    time counts in it); `frame_drop`: that share of the frames gives no estimate (drawn per frame, seeded)."""

    def __init__(
        self,
        plant: CellView | None,
        calibration_path: str | Path | None,
        object_size: float,
        arm: ArmDrawing | MujocoDrawing,
        noise_seed: int = 0,
        hmd_overrides: dict | None = None,
        max_age: float = 3.0,
        start_timeout: float = 180.0,
    ):
        """Start the HMD process and wait until it has calibrated; with `plant`, start streaming at once. The
        process draws `arm` (posed as the plant's joints are).

        Without one, `attach` starts it later: start the process before a simulated cell's control loop runs,
        since its calibration renders for seconds and would take the CPU from the 4 ms loop."""
        self.plant = plant
        self.max_age = max_age
        from mrguide.calibration.config import load_calibration_config

        noise = replace(load_calibration_config(calibration_path).hmd, seed=noise_seed, **(hmd_overrides or {}))
        self.latency, self._drop, self._look_sigma = noise.latency_s, noise.frame_drop, noise.tracking_noise_m
        self._drops = np.random.default_rng([noise_seed, 402])  # which frames the HMD loses
        ctx = mp.get_context("spawn")
        self._conn, child = ctx.Pipe()
        self._proc = ctx.Process(
            target=_hmd_worker,
            args=(
                child,
                str(calibration_path) if calibration_path else None,
                object_size,
                noise_seed,
                hmd_overrides or {},
                arm,
            ),
            name="hmd",
            daemon=True,
        )
        _start(self._proc, offscreen_gl=isinstance(arm, MujocoDrawing))
        self.calibration = self._wait_ready(start_timeout)
        self._latest: tuple[np.ndarray, float] | None = None
        self._pending: deque[tuple[np.ndarray, float]] = deque()  # estimates made, not yet through the latency
        self._generation = 0
        self.frames = self.misses = 0
        self._lost: str | None = None  # why the HMD process can give no more estimates
        self._given: float | None = None  # when the scene behind the estimate last given was seen (monotonic)
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="hmd-stream", daemon=True)
        if plant is not None:
            self._thread.start()

    def attach(self, plant: CellView) -> HmdPoseStream:
        """Stream the object of `plant` (once; the process was started and calibrated without it)."""
        if self.plant is not None:
            raise RuntimeError("the HMD stream already follows a twin")
        self.plant = plant
        self._thread.start()
        return self

    def _wait_ready(self, timeout: float) -> dict:
        """The worker's start-up report; HmdStartError if it fails, dies or stays silent for `timeout` s."""
        end = time.monotonic() + timeout
        while not self._conn.poll(0.1):
            if not self._proc.is_alive():
                raise HmdStartError(f"HMD process exited during start-up (exit code {self._proc.exitcode})")
            if time.monotonic() > end:
                self._proc.kill()
                raise HmdStartError(f"HMD process did not start within {timeout} s")
        kind, info = self._conn.recv()
        if kind != "ready":
            raise HmdStartError(f"HMD process failed to start: {info}")
        return info

    def _run(self) -> None:
        plant = self.plant
        assert plant is not None  # the thread starts once a twin is attached
        while not self._stop.is_set():
            gen = self._generation
            try:
                pos, orn, q = plant.view()
            except Exception as exc:  # the twin playing the robot was closed under us (end of a run) or failed
                with self._lock:
                    self._lost = f"the twin that plays the robot is gone ({type(exc).__name__}: {exc})"
                log.debug("HMD stream stops: %s", self._lost)
                return
            t = time.monotonic()
            try:
                self._conn.send((pos.tolist(), orn.tolist(), q.tolist()))
                kind, value = self._conn.recv()
            except Exception as exc:  # EOF, a broken pipe, a garbled message: no more estimates, say so
                self._proc.join(timeout=1.0)
                with self._lock:
                    self._lost = f"the HMD process went away (exit code {self._proc.exitcode}; {type(exc).__name__})"
                log.warning("%s: no more object poses from the HMD", self._lost)
                return
            if kind == "pose" and self._drop and self._drops.random() < self._drop:
                kind = "dropped"
            with self._lock:
                self.frames += 1
                if kind == "pose" and gen == self._generation:
                    self._pending.append((np.asarray(value, dtype=float), t))
                elif kind != "pose":
                    self.misses += 1
            self._stop.wait(t + 1.0 / MAX_FRAME_RATE - time.monotonic())

    def invalidate(self) -> None:
        """Forget the current estimate (the object was moved by hand)."""
        with self._lock:
            self._generation += 1
            self._latest = None
            self._pending.clear()

    def _arrived(self) -> tuple[np.ndarray, float] | None:
        """The newest estimate whose scene was seen at least `latency` s ago (call under the lock)."""
        now = time.monotonic()
        while self._pending and self._pending[0][1] + self.latency <= now:
            self._latest = self._pending.popleft()
        return self._latest

    def wait_fresh(self, timeout: float = 10.0) -> None:
        """Wait for an estimate made after the last `invalidate`; PoseUnavailable after `timeout` s, or at
        once if the HMD process is gone."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            with self._lock:
                if self._arrived() is not None:
                    return
            self._raise_if_lost()
            time.sleep(0.02)
        raise PoseUnavailable(f"no HMD estimate of the object within {timeout} s")

    def _raise_if_lost(self) -> None:
        with self._lock:
            lost = self._lost
        # the process's sentinel, not is_alive(): is_alive() can report a dead child as alive while the
        # reader thread is reaping it (waitpid then fails with ECHILD and the exit code is not yet stored)
        if lost is None and mp.connection.wait([self._proc.sentinel], timeout=0):
            lost = f"the HMD process is not running (exit code {self._proc.exitcode})"
        if lost is not None:
            raise PoseUnavailable(lost)

    def object_position(self) -> np.ndarray:
        """The latest estimate; PoseUnavailable if there is none yet, it is older than `max_age`, or the HMD
        process is gone (at once: the deploy runtime then decides how long the last pose may serve)."""
        self._raise_if_lost()
        with self._lock:
            latest = self._arrived()
        if latest is None:
            raise PoseUnavailable("the HMD has not seen the object marker yet")
        pos, t = latest
        age = time.monotonic() - t
        if age > self.max_age:
            raise PoseUnavailable(f"the last HMD estimate is {age:.2f} s old")
        self._given = t
        return pos.copy()

    def accuracy_m(self) -> float:
        """`PoseAccuracy`: three times the registration's RMS residual and one look's tracking noise together."""
        return 3.0 * math.hypot(self.calibration["rms_residual_m"], self._look_sigma)

    def pose_details(self) -> dict:
        """For the run log: the age of the estimate `object_position` gave last (from the moment the HMD saw the
        scene it was made from), and where the object is in the twin now."""
        details: dict = {"age_s": None if self._given is None else time.monotonic() - self._given}
        if self.plant is not None:
            details["true"] = self.plant.object_position()
        return details

    def close(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=10)
        stop_render_process(self._conn, self._proc)
