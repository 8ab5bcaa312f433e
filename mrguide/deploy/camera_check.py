"""`mrguide camera check`: run the configured camera pose source for N frames and show what it sees.

Prints one line per frame (marker seen or why not, capture->pose latency, object position in the robot frame),
then the detection rate, latency median/p95 and poses/s, and writes an overlay PNG of the last frame with a
pose (marker outline, id and axes). No PyBullet, no torch: it runs on the robot PC. The handler imports
OpenCV and the camera pipeline itself: the `mrguide` parser is built without them.
"""

from __future__ import annotations

import argparse
import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from mrguide.cli_args import positive_float, positive_int
from mrguide.output_files import check_output_file, write_files_atomically

if TYPE_CHECKING:
    from mrguide.calibration.pose_sources import MarkerObservation
    from mrguide.deploy.camera import CameraPoseSource
    from mrguide.deploy.frames import Frame


def add_camera_command(subparsers: argparse._SubParsersAction) -> None:
    """Add `camera check` to the top-level parser; its handler returns the exit code."""
    p = subparsers.add_parser("camera", help="the deploy camera: `camera check` shows detection rate, latency, pose")
    sub = p.add_subparsers(dest="camera_command", required=True)
    c = sub.add_parser(
        "check",
        help="run the [deploy.camera] source for N frames; rate, latency, pose, overlay PNG",
        description="Open the camera of [deploy.camera] (device, stream or image folder), run N frames "
        "through the marker pipeline, print each frame's result and the detection rate, capture->pose "
        "latency and poses/s, and write an overlay PNG of the last frame with a pose.",
    )
    c.add_argument("--config", type=Path, help="TOML with [deploy.camera]")
    c.add_argument("--frames", type=positive_int, default=60, help="frames to process (default 60)")
    c.add_argument("--timeout", type=positive_float, default=60.0, help="give up after this many seconds (default 60)")
    c.add_argument("--overlay", type=Path, default=Path("out/camera_check.png"), help="overlay PNG to write")
    c.set_defaults(func=run_camera_check, command_name="camera check")


def run_camera_check(args: argparse.Namespace) -> int:
    """Exit 0 when at least one pose was found, 1 when none was, 2 on bad input."""
    from mrguide.calibration.overlay import can_write_image
    from mrguide.config import load_section
    from mrguide.deploy.camera import open_camera_source
    from mrguide.deploy.frames import CameraError
    from mrguide.deploy.session import DeployConfig

    check_output_file(args.overlay, "--overlay")
    if not can_write_image(args.overlay):
        raise CameraError(
            f"--overlay {args.overlay}: OpenCV cannot write images with extension {args.overlay.suffix!r} (use .png)"
        )
    cfg = load_section(DeployConfig, args.config, "deploy").camera
    base = args.config.parent if args.config else Path.cwd()
    done = threading.Event()
    shown = 0
    view: tuple[Frame, MarkerObservation] | None = None  # the last frame with a pose

    def on_frame(frame: Frame, seen: MarkerObservation) -> None:
        nonlocal shown, view
        shown += 1
        if seen.position is not None:
            view = (frame, seen)
            where = f"object at {np.round(seen.position, 4).tolist()} m"
        else:
            where = seen.problem
        print(f"frame {shown:4d}  latency {(time.monotonic() - frame.t_capture) * 1e3:6.1f} ms  {where}")
        if shown >= args.frames:
            done.set()

    source = open_camera_source(cfg, base, on_frame)
    try:
        end = time.monotonic() + args.timeout
        while not done.wait(0.1) and source.running() and time.monotonic() < end:
            pass
    finally:
        source.close()
    if source.error is not None:
        raise source.error
    return _report(source, view, args.overlay)


def _report(source: CameraPoseSource, view: tuple[Frame, MarkerObservation] | None, overlay: Path) -> int:
    from mrguide.calibration.overlay import draw_overlay, encode_image

    stats = source.stats()
    print(stats.text())
    if view is None:
        print(f"marker {source.pipeline.marker_id} was never seen; no overlay written")
        return 1
    frame, seen = view
    assert seen.pose is not None and seen.position is not None  # kept only when it gave a position
    position = np.round(seen.position, 4).tolist()
    print(f"object (marker {source.pipeline.marker_id}) in the robot frame: {position} m")
    image = draw_overlay(
        frame.image,
        seen.detections,
        [(seen.pose, 0.75 * source.pipeline.detector.marker_size_m)],
        source.pipeline.camera,
        f"object {position} m, {stats.detection_rate:.0%} detected",
    )
    write_files_atomically({overlay: encode_image(image, overlay)})
    print(f"wrote {overlay}")
    return 0
