"""Episodes as a Rerun recording (`mrguide replay`). Needs the `replay` extra (rerun-sdk).

Per episode, under `/<label>/` (see `Episode.label`): the arm from its URDF (Rerun's URDF support,
`rerun.urdf.UrdfTree`), posed by the measured joints on the `decision` timeline; the commanded TCP target and
the arrow to it; the TCP trail; the object as the policy saw it and, where the log has it, where it really
was (with the estimate's age in its label); the goal; markers where the supervisor reported an event and
where the episode ended. Scalars under `/plots/<quantity>/<label>` (vacuum, part signal, φ, decision latency,
pose age), the phase as a state timeline under `/phase/<label>`, and every event as a text log line under
`/events/<label>`. All episodes share the `decision` timeline (t = 0 at each episode's start) and `time`
(t × the decision period), so episodes play side by side.
"""

from __future__ import annotations

import re
import tempfile
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import rerun as rr

from mrguide.cell_layout import CUP_RADIUS
from mrguide.replay.runs import Episode, Frame
from mrguide.robot import RobotSpec, urdf_with_tool
from mrguide.task import PHASES

APPLICATION_ID = "mrguide_replay"
OBJECT_HALF = 0.025  # m, half the default object edge (task.object_height)

COLORS = {
    "success": (40, 170, 60),
    "dropped": (220, 40, 40),
    "no_grasp": (230, 150, 20),
    "misplaced": (200, 120, 200),
    "knocked_off": (150, 60, 20),
    "timeout": (120, 120, 120),
}
OTHER = (60, 110, 220)
#: Where the 3D view looks from and at (robot base frame, m): across the table at the object and goal regions.
EYE, LOOK_AT = (1.25, -0.85, 0.65), (0.45, 0.0, 0.1)


def replay_urdf(spec: RobotSpec, folder: Path) -> tuple[Path, list[tuple[str, np.ndarray, np.ndarray]]]:
    """The arm's URDF for the viewer and the link meshes to draw with it: (URDF path, [(link, vertices, faces)]).

    The URDF is the twin's (the suction cup and TCP link added) without collision elements and without mesh
    visuals; Rerun's URDF support logs its frames, joints and primitive shapes (the cup). The link meshes are
    the URDF's STL meshes (for a Collada visual, the STL collision mesh of the same name: example-robot-data's
    UR visuals are Collada), read here with the visual's origin applied, to be logged as `Mesh3D` in the link's
    frame: the URDF loader's own STL assets did not draw in the web viewer under a software renderer."""
    root = ET.fromstring(urdf_with_tool(spec, f"{spec.package_dir.as_posix()}/", CUP_RADIUS))
    meshes = []
    for link in root.iter("link"):
        for collision in list(link.findall("collision")):
            link.remove(collision)
        for visual in list(link.findall("visual")):
            mesh = visual.find("geometry/mesh")
            if mesh is None:
                continue
            link.remove(visual)
            name = mesh.get("filename", "")
            stl = Path(re.sub(r"/visual/([^/]+)\.dae$", r"/collision/\1.stl", name))
            if stl.suffix.lower() == ".stl" and stl.is_file():
                vertices, faces = _read_stl(stl)
                meshes.append((link.get("name", ""), _place(vertices, visual.find("origin")), faces))
    path = folder / f"{spec.name}-replay.urdf"
    path.write_text(ET.tostring(root, encoding="unicode"))
    return path, meshes


def _read_stl(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (n×3) and triangles (m×3) of a binary STL."""
    data = path.read_bytes()
    count = int(np.frombuffer(data, "<u4", 1, 80)[0])
    rows = np.frombuffer(data, np.dtype([("n", "<3f4"), ("v", "<9f4"), ("a", "<u2")]), count, 84)
    vertices = rows["v"].reshape(-1, 3).astype(float)
    return vertices, np.arange(len(vertices)).reshape(-1, 3)


def _place(vertices: np.ndarray, origin: ET.Element | None) -> np.ndarray:
    """`vertices` moved by a URDF origin (xyz, then roll-pitch-yaw about fixed x, y, z)."""
    if origin is None:
        return vertices
    x, y, z = (float(v) for v in (origin.get("xyz") or "0 0 0").split())
    r, p, w = (float(v) for v in (origin.get("rpy") or "0 0 0").split())
    cr, sr, cp, sp, cw, sw = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(w), np.sin(w)
    R = np.array(
        [
            [cw * cp, cw * sp * sr - sw * cr, cw * sp * cr + sw * sr],
            [sw * cp, sw * sp * sr + cw * cr, sw * sp * cr - cw * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )
    return vertices @ R.T + np.array([x, y, z])


def color(outcome: str | None) -> tuple[int, int, int]:
    return COLORS.get(outcome or "", OTHER)


def write_recording(
    episodes: Sequence[Episode],
    spec: RobotSpec,
    save: str | Path | None = None,
    spawn: bool = False,
    arms: bool = True,
    name: str = "replay",
) -> Any:
    """Log `episodes` into one recording, saved to `save` (.rrd) and/or sent to a spawned viewer; returns it."""
    rec = rr.RecordingStream(APPLICATION_ID, recording_id=name)
    blueprint = _blueprint(episodes)
    if spawn:
        rec.spawn(default_blueprint=blueprint)
    if save is not None:
        Path(save).parent.mkdir(parents=True, exist_ok=True)
        rec.save(str(save), default_blueprint=blueprint)
    elif not spawn:
        raise ValueError("write_recording needs save or spawn")
    rec.log("/", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    with tempfile.TemporaryDirectory(prefix="mrguide-replay-") as tmp:
        arm = replay_urdf(spec, Path(tmp)) if arms else None
        for ep in episodes:
            _log_episode(rr, rec, ep, spec, arm)
    rec.flush()
    return rec


def _blueprint(episodes: Sequence[Episode]) -> Any:
    import rerun.blueprint as rrb

    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(
                name="cell",
                origin="/",
                contents=["/**", "- /plots/**", "- /phase/**", "- /events/**"],
                eye_controls=rrb.EyeControls3D(position=EYE, look_target=LOOK_AT, eye_up=(0.0, 0.0, 1.0)),
            ),
            rrb.Vertical(
                rrb.StateTimelineView(name="phase", origin="/phase"),
                rrb.TimeSeriesView(name="vacuum (kPa)", origin="/plots/vacuum_kpa"),
                rrb.TimeSeriesView(name="part present", origin="/plots/part"),
                rrb.TimeSeriesView(name="φ", origin="/plots/phi"),
                rrb.TimeSeriesView(name="decision latency (ms)", origin="/plots/latency_ms"),
                rrb.TextLogView(name="events", origin="/events"),
            ),
            column_shares=[3, 2],
        ),
        collapse_panels=False,
    )


def _log_episode(rr: Any, rec: Any, ep: Episode, spec: RobotSpec, arm: tuple | None) -> None:
    """Log one episode: its static entities (coordinate frames, arm, goal), then each frame on the shared timelines."""
    label = ep.label
    base = f"/{label}"
    rgb = color(ep.outcome)
    frames = ep.frames
    world = f"{label}/world"
    # one shared world frame: each episode's arm tree hangs below it, its other entities sit in it
    rec.log(f"{base}/frame", rr.Transform3D(parent_frame="world", child_frame=world), static=True)
    for part in ("tcp", "trail", "target", "command", "object/seen", "object/true", "goal", "markers"):
        rec.log(f"{base}/{part}", rr.CoordinateFrame(world), static=True)
    joints = []
    if arm is not None and frames and frames[0].q is not None:
        joints = _log_arm(rr, rec, label, spec, arm)
    if ep.goal is not None:
        rec.log(
            f"{base}/goal",
            rr.Boxes3D(centers=[ep.goal], half_sizes=[[0.03, 0.03, 0.001]], colors=[(40, 200, 80, 120)]),
            static=True,
        )
    trail: list[np.ndarray] = []
    summary = f"{label}: {ep.kind} episode {ep.index}, outcome {ep.outcome}"
    event_at: dict[int, list[dict]] = {}
    for e in ep.events:
        event_at.setdefault(int(e.get("t") or 0), []).append(e)
    last_phase = None
    for f in frames:
        rec.set_time("decision", sequence=f.t)
        rec.set_time("time", duration=f.t * ep.decision_period)
        if f.t == 0:
            rec.log(f"/events/{label}", rr.TextLog(summary, level="INFO"))
        _log_arm_pose(rr, rec, base, f, joints, trail, rgb)
        _log_object(rr, rec, base, f)
        if f.phase != last_phase:
            rec.log(f"/phase/{label}", rr.StateChange(state=PHASES[f.phase]))
            rec.log(f"/events/{label}", rr.TextLog(f"{label}: phase {PHASES[f.phase]}", level="DEBUG"))
            last_phase = f.phase
        _log_scalars(rr, rec, label, f)
        _log_events(rr, rec, label, f, event_at.get(f.t, []), rgb)


def _log_arm(rr: Any, rec: Any, label: str, spec: RobotSpec, arm: tuple) -> list:
    """Log the arm's URDF tree and link meshes (static) under `/<label>/`; returns its joints in `spec`'s order."""
    base = f"/{label}"
    urdf, meshes = arm
    tree = rr.urdf.UrdfTree.from_file_path(
        urdf, entity_path_prefix=label, frame_prefix=f"{label}/", static_transform_entity_path=f"{base}/tf_static"
    )
    tree.log_urdf_to_recording(rec)
    joints = [tree.get_joint_by_name(n) for n in spec.joint_names]
    for link, vertices, faces in meshes:
        path = f"{base}/{tree.name}/meshes/{link}"
        rec.log(path, rr.CoordinateFrame(f"{label}/{link}"), static=True)
        rec.log(
            path,
            rr.Mesh3D(vertex_positions=vertices, triangle_indices=faces, albedo_factor=(0.72, 0.74, 0.78, 1.0)),
            static=True,
        )
    return joints


def _log_arm_pose(
    rr: Any, rec: Any, base: str, f: Frame, joints: list, trail: list[np.ndarray], rgb: tuple[int, int, int]
) -> None:
    """Log one frame's joints, TCP (appended to `trail`), commanded target and the arrow to it."""
    if joints and f.q is not None:
        for joint, q in zip(joints, f.q):
            rec.log(f"{base}/joints", joint.compute_transform(float(q), clamp=False))
    if f.tcp is not None:
        trail.append(f.tcp)
        rec.log(f"{base}/tcp", rr.Points3D([f.tcp], radii=0.006, colors=[rgb]))
        rec.log(f"{base}/trail", rr.LineStrips3D([np.array(trail)], radii=0.002, colors=[rgb]))
    if f.target is not None:
        rec.log(f"{base}/target", rr.Points3D([f.target], radii=0.008, colors=[(250, 200, 0)]))
        if f.tcp is not None:
            rec.log(f"{base}/command", rr.Arrows3D(origins=[f.tcp], vectors=[f.target - f.tcp], colors=[(250, 200, 0)]))


def _log_object(rr: Any, rec: Any, base: str, f: Frame) -> None:
    """Log one frame's object: as the policy saw it (with the estimate's age) and where it really was."""
    if f.obj is not None:
        age = f" ({f.pose_age_s * 1e3:.0f} ms old)" if f.pose_age_s is not None and f.object_from == "source" else ""
        rec.log(
            f"{base}/object/seen",
            rr.Boxes3D(
                centers=[f.obj],
                half_sizes=[[OBJECT_HALF] * 3],
                colors=[(90, 140, 255)],
                fill_mode="MajorWireframe",
                labels=[f"seen: {f.object_from or 'source'}{age}"],
            ),
        )
    if f.obj_true is not None:
        rec.log(
            f"{base}/object/true",
            rr.Boxes3D(centers=[f.obj_true], half_sizes=[[OBJECT_HALF] * 3], colors=[(200, 30, 30)], fill_mode="Solid"),
        )


def _log_scalars(rr: Any, rec: Any, label: str, f: Frame) -> None:
    """Log one frame's plotted quantities under `/plots/<quantity>/<label>`."""
    if f.phi is not None:
        rec.log(f"/plots/phi/{label}", rr.Scalars(f.phi))
    if f.vacuum_kpa is not None:
        rec.log(f"/plots/vacuum_kpa/{label}", rr.Scalars(float(f.vacuum_kpa)))
    if f.part is not None:
        rec.log(f"/plots/part/{label}", rr.Scalars(float(bool(f.part))))
    if f.latency_ms is not None:
        rec.log(f"/plots/latency_ms/{label}", rr.Scalars(float(f.latency_ms)))
    if f.pose_age_s is not None and f.object_from == "source":
        rec.log(f"/plots/pose_age_ms/{label}", rr.Scalars(float(f.pose_age_s) * 1e3))


def _log_events(rr: Any, rec: Any, label: str, f: Frame, events: list[dict], rgb: tuple[int, int, int]) -> None:
    """Log one frame's supervisor `events` and the episode's end, as log lines and markers at the TCP."""
    base = f"/{label}"
    for e in events:
        text = f"{label}: {e['event']} → {e.get('reaction')}: {e.get('detail')}"
        rec.log(f"/events/{label}", rr.TextLog(text, level="WARN"))
        if f.tcp is not None:
            rec.log(f"{base}/markers", rr.Points3D([f.tcp], radii=0.012, colors=[(255, 140, 0)], labels=[e["event"]]))
    if f.outcome is not None:
        level = "INFO" if f.outcome == "success" else "ERROR"
        rec.log(f"/events/{label}", rr.TextLog(f"{label}: {f.outcome} at t = {f.t}", level=level))
        if f.tcp is not None:
            rec.log(f"{base}/markers", rr.Points3D([f.tcp], radii=0.014, colors=[rgb], labels=[f.outcome]))
