"""The simulated HMD's latency and frame drops (`[calibration.hmd]` `latency_s`, `frame_drop`): an estimate reaches
the runtime only `latency_s` after its scene was seen, and about `frame_drop` of the frames give none."""

import time
from pathlib import Path

from mrguide.cell.config import CellConfig
from mrguide.cell.hmd_stream import HmdPoseStream
from mrguide.cell.twin_plant import TwinPlant
from mrguide.parts import part_named
from mrguide.robot import load_robot
from mrguide.twin.scene import Scene
from mrguide.twin.visual_arm import ArmDrawing

REAL = Path(__file__).parents[2] / "configs" / "cells" / "real_cell.toml"
LATE_AND_LOSSY = {"latency_s": 0.4, "frame_drop": 0.5}


def test_estimates_arrive_after_the_latency_and_dropped_frames_give_none():
    cfg = CellConfig.load(REAL)
    scene = Scene(load_robot(cfg.robot), cfg.twin, part_named(cfg.task.part))
    drawing = ArmDrawing.of(scene.spec)
    stream = HmdPoseStream(TwinPlant(scene), REAL, cfg.task.object_height, drawing, hmd_overrides=LATE_AND_LOSSY)
    try:
        assert (stream.latency, stream._drop) == (0.4, 0.5)
        # its stated accuracy (`PoseAccuracy`): the registration's residual beside one look's noise, three times
        residual = stream.calibration["rms_residual_m"]
        assert 3.0 * max(residual, 0.003) <= stream.accuracy_m() <= 3.0 * (residual + 0.003)  # the cell's 3 mm looks
        for _ in range(3):
            stream.invalidate()
            stream.wait_fresh(timeout=60.0)
            stream.object_position()
            assert stream.pose_details()["age_s"] >= 0.4  # never an estimate younger than the latency
        end = time.monotonic() + 120.0
        while stream.frames < 30 and time.monotonic() < end:
            time.sleep(0.1)
        assert stream.frames >= 30
        assert 0.2 * stream.frames < stream.misses < 0.8 * stream.frames  # seeded draws: 15 ± 2.7 of 30 expected
    finally:
        stream.close()
        scene.close()
