"""`mrguide calibrate`: register the HMD (or a fixed camera) to the robot base from images or the twin.

The handler imports OpenCV and the calibration modules itself: the `mrguide` parser is built without them.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from tqdm import tqdm

from mrguide.calibration.errors import CalibrationError
from mrguide.output_files import check_output_file, write_files_atomically

if TYPE_CHECKING:
    from mrguide.calibration.camera_model import CameraModel
    from mrguide.calibration.config import CalibrationConfig
    from mrguide.calibration.procedure import CalibrationRun

log = logging.getLogger(__name__)

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")


def add_calibrate_command(
    subparsers: argparse._SubParsersAction,
    twin_calibration: Callable[[Path | None, CalibrationConfig], tuple[CalibrationRun, np.ndarray]],
) -> None:
    """Add `calibrate` to the top-level parser; its handler returns the exit code. `twin_calibration(config,
    cfg)` renders the targets with the twin's HMD and calibrates (handed in by the twin: calibration does not
    import it) and returns the run and the true T_base_hmd."""
    p = subparsers.add_parser(
        "calibrate",
        help="register the HMD/camera frame to the robot base with ArUco markers",
        description="Detect the calibration board/markers (placed as in [calibration.targets]) in images or in the "
        "twin, register the HMD frame to the robot base, print residuals, write the calibration file and an "
        "overlay PNG with the detected markers and axes.",
    )
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--images", type=Path, metavar="DIR", help="folder of images of the targets")
    src.add_argument("--twin", action="store_true", help="render the targets with the twin's simulated HMD")
    p.add_argument("--intrinsics", type=Path, help="camera intrinsics (.json/.toml/.yaml/.xml); required with --images")
    p.add_argument(
        "--poses",
        type=Path,
        help="JSON {image file name: 4x4 T_hmd_cam} from head tracking; without it the camera frame "
        "is the registered frame (a fixed camera)",
    )
    p.add_argument("--config", type=Path, help="TOML with [calibration] (and [calibration_twin] for --twin)")
    p.add_argument("--out", type=Path, default=Path("out/calibration.json"), help="calibration file to write")
    p.add_argument("--overlay", type=Path, default=Path("out/calibration_overlay.png"), help="overlay PNG to write")
    p.set_defaults(func=run_calibrate, twin_calibration=twin_calibration)


def run_calibrate(args: argparse.Namespace) -> int:
    """Bad input raises CalibrationError/ConfigError before anything is written; both files are written together."""
    from mrguide.calibration.camera_model import load_camera_model
    from mrguide.calibration.config import load_calibration_config
    from mrguide.calibration.overlay import encode_image, mosaic
    from mrguide.calibration.procedure import calibrate_frames

    _check_outputs(args.out, args.overlay)
    cfg = load_calibration_config(args.config)
    if args.twin:
        run, truth = args.twin_calibration(args.config, cfg)
    else:
        if args.intrinsics is None:
            raise CalibrationError("--images needs --intrinsics FILE (the camera matrix of the images' camera mode)")
        camera = load_camera_model(args.intrinsics)
        frames = _image_frames(args.images, camera, args.poses)
        run, truth = calibrate_frames(tqdm(frames, desc="frames", disable=not sys.stderr.isatty()), cfg, camera), None
    _report(run, truth)
    write_files_atomically(
        {args.out: run.record.encode(), args.overlay: encode_image(mosaic(run.overlays), args.overlay)}
    )
    print(f"wrote {args.out} and {args.overlay}")
    return 0


def _check_outputs(out: Path, overlay: Path) -> None:
    """Refuse output locations that cannot be written, before any work is done."""
    from mrguide.calibration.overlay import can_write_image

    check_output_file(out, "--out")
    check_output_file(overlay, "--overlay")
    if not can_write_image(overlay):
        raise CalibrationError(
            f"--overlay {overlay}: OpenCV cannot write images with extension {overlay.suffix!r} (use .png)"
        )
    if out.resolve() == overlay.resolve():
        raise CalibrationError(f"--out and --overlay are the same file: {out}")


def _image_frames(folder: Path, camera: CameraModel, poses_path: Path | None):
    """(label, RGB image, T_hmd_cam) for every image in `folder`, checked against the intrinsics."""
    import cv2

    if not folder.is_dir():
        raise CalibrationError(f"image folder not found: {folder}")
    files = sorted(f for f in folder.iterdir() if f.suffix.lower() in IMAGE_SUFFIXES)
    if not files:
        raise CalibrationError(f"{folder}: no images ({', '.join(IMAGE_SUFFIXES)})")
    poses = _load_poses(poses_path, [f.name for f in files]) if poses_path else {}
    frames = []
    for f in files:
        bgr = cv2.imread(str(f), cv2.IMREAD_COLOR)
        if bgr is None:
            raise CalibrationError(f"{f}: cannot read the image (corrupt or not an image)")
        rgb = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
        camera.check_image(rgb, str(f))
        frames.append((f.name, rgb, poses.get(f.name, np.eye(4))))
    return frames


def _load_poses(path: Path, names: list[str]) -> dict[str, np.ndarray]:
    from mrguide.calibration.se3 import is_rigid

    try:
        data = json.loads(path.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise CalibrationError(f"{path}: cannot read the head-tracking poses: {exc}") from exc
    if not isinstance(data, dict):
        raise CalibrationError(f"{path}: expected an object {{image name: 4x4 matrix}}")
    missing = [n for n in names if n not in data]
    if missing:
        raise CalibrationError(f"{path}: no pose for {', '.join(missing)}")
    poses = {}
    for name in names:
        try:
            T = np.asarray(data[name], dtype=float)
        except (TypeError, ValueError) as exc:
            raise CalibrationError(f"{path}: pose of {name} is not a numeric 4x4 matrix") from exc
        if not is_rigid(T, tol=1e-4):
            raise CalibrationError(f"{path}: pose of {name} is not a rigid 4x4 transform")
        poses[name] = T
    return poses


def _report(run: CalibrationRun, truth: np.ndarray | None) -> None:
    from mrguide.calibration.se3 import apply, invert, rotation_angle_deg

    reg, T = run.registration, run.registration.T_base_hmd
    print(f"{'frame':<24}{'markers':>8}{'rms mm':>9}{'max mm':>9}  status")
    for f in run.frames:
        if f.label in reg.frames_used:
            r = np.linalg.norm(apply(T, f.points_hmd) - f.points_base, axis=1) * 1e3
            print(f"{f.label:<24}{f.n_markers:>8}{np.sqrt(np.mean(r**2)):>9.2f}{r.max():>9.2f}  used")
        else:
            print(f"{f.label:<24}{f.n_markers:>8}{'-':>9}{'-':>9}  rejected: {reg.frames_rejected.get(f.label, '')}")
    print(
        f"registration: {len(reg.frames_used)} frames, {len(reg.residuals_m)} points, "
        f"rms {reg.rms_m * 1e3:.2f} mm, max {reg.max_m * 1e3:.2f} mm"
    )
    with np.printoptions(precision=5, suppress=True):
        print(f"T_base_hmd =\n{T}")
    if truth is not None:
        centre = np.array([0.475, 0.1, 0.0])  # workspace centre
        print(
            f"twin ground truth: translation error {np.linalg.norm(T[:3, 3] - truth[:3, 3]) * 1e3:.2f} mm, "
            f"rotation error {rotation_angle_deg(truth[:3, :3], T[:3, :3]):.3f} deg, "
            f"error at the workspace centre {np.linalg.norm(apply(T @ invert(truth), centre) - centre) * 1e3:.2f} mm"
        )
