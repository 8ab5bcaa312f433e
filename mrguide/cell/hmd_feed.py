"""The `hmd` pose source of `deploy --dry-run`: the cell's simulated headset (`hmd_stream`), as sim2real's HMD
conditions play it, behind the interface the deploy command gives its pose feeds (`__call__` is the dry run's
pose factory, `refresh` its on_placed, `stats` and `close`)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from mrguide.cell.config import CellConfig
from mrguide.cell.hmd_stream import HmdPoseStream, MujocoDrawing
from mrguide.robot import load_robot
from mrguide.twin.visual_arm import ArmDrawing


@dataclass(frozen=True)
class HmdStats:
    """What the headset gave over the run: frames answered, frames without a pose (marker hidden or lost)."""

    frames: int
    misses: int

    def as_dict(self) -> dict:
        return {"frames": self.frames, "misses": self.misses}

    def text(self) -> str:
        return f"HMD: {self.frames} frames, {self.misses} without a pose of the part"


class HmdFeed:
    """The simulated headset of the cell of `cfg` (its `[calibration.hmd]` in `path`, `overrides` set over it), drawn
    by the cell's engine, calibrated at once (seconds of rendering, before the cell's control loop starts); its errors
    drawn from `seed`. Serves one cell."""

    def __init__(self, cfg: CellConfig, path: Path | None, seed: int, overrides: dict | None = None):
        spec = load_robot(cfg.robot)
        drawing = MujocoDrawing(spec, cfg.twin.cup) if cfg.plant.engine == "mujoco" else ArmDrawing.of(spec)
        height = cfg.task.object_height
        self.stream = HmdPoseStream(None, path, height, drawing, noise_seed=seed, hmd_overrides=overrides)

    def __call__(self, cell) -> HmdPoseStream:
        return self.stream.attach(cell.plant)

    def refresh(self) -> None:
        """The part was just placed: wait for a pose the headset made after that."""
        self.stream.invalidate()
        self.stream.wait_fresh()

    def stats(self) -> HmdStats:
        return HmdStats(self.stream.frames, self.stream.misses)

    def close(self) -> None:
        self.stream.close()
