"""The lift drops of a sim-to-real experiment beside clean lifts, from its per-episode run logs (docs/replay.md).

    python -m mrguide.replay.lift_drops [RUN_DIR] [OUT_DIR]

RUN_DIR defaults to docs/results/history/sim2real-anchor-offset/guided (its seed*/sim2real/log-*.jsonl.gz), OUT_DIR
to docs/results/replay.

Writes OUT_DIR/drops.rrd (every drop and ten clean lifts, side by side: `rerun OUT_DIR/drops.rrd`), OUT_DIR/lifts.png
(vacuum, TCP height and the commanded height ahead of the TCP, against decisions since the lift began) and
prints one line per episode: the numbers docs/replay.md quotes. The clean lifts are the first successful episode of
each of the 18 logs, in file order, until ten are taken.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from mrguide.replay.recording import write_recording
from mrguide.replay.runs import load_run
from mrguide.robot import load_robot
from mrguide.task import Phase

RUN = Path("docs/results/history/sim2real-anchor-offset/guided")  # the default RUN_DIR, from the repository root


def lift(ep):
    """The frames from the first lift decision (phase 2) on."""
    start = next(i for i, f in enumerate(ep.frames) if f.phase == Phase.LIFT)
    return ep.frames[start:]


def numbers(ep) -> dict:
    frames = lift(ep)
    frames = frames[: next((i + 1 for i, f in enumerate(frames) if f.phase != Phase.LIFT or f.outcome), len(frames))]
    first = frames[0]
    acting = [f for f in frames if f.q is not None and f.phase == Phase.LIFT]
    z = [f.tcp[2] for f in frames]
    off = np.linalg.norm(first.tcp[:2] - first.obj[:2]) * 1e3
    lateral = max(np.linalg.norm(f.target[:2] - f.tcp[:2]) for f in acting if f.target is not None) * 1e3
    grasp = [f for f in ep.frames if f.phase == Phase.GRASP and f.target is not None]
    return {
        "lift decisions": len(acting),  # phase-2 decisions acted on
        "vacuum at lift start (kPa)": first.vacuum_kpa,
        "peak vacuum in lift (kPa)": max(f.vacuum_kpa for f in acting),
        "cup offset at lift start (mm)": off,
        "TCP z at lift start (mm)": first.tcp[2] * 1e3,
        "TCP z at end (mm)": z[-1] * 1e3,
        "max lateral command in lift (mm)": lateral,
        "deepest grasp target below top (mm)": (first.obj[2] + 0.025 - min(f.target[2] for f in grasp)) * 1e3,
        "lift target z (mm)": acting[0].target[2] * 1e3 if acting[0].target is not None else float("nan"),
        "rise in 1st decision (mm)": (z[1] - z[0]) * 1e3,
        "rise in 2nd decision (mm)": (z[2] - z[1]) * 1e3 if len(z) > 2 else float("nan"),
        "vacuum after 1st decision (kPa)": frames[1].vacuum_kpa if frames[1].vacuum_kpa is not None else float("nan"),
    }


def main() -> int:
    run = Path(sys.argv[1]) if len(sys.argv) > 1 else RUN
    out = Path(sys.argv[2] if len(sys.argv) > 2 else "docs/results/replay")
    logs = sorted(run.glob("seed*/sim2real/log-*.jsonl.gz"))
    if not logs:
        print(f"no seed*/sim2real/log-*.jsonl.gz under {run}", file=sys.stderr)
        return 2
    episodes = [e for log in logs for e in load_run(log)]
    drops = [e for e in episodes if e.outcome == "dropped"]
    clean: list = []
    for log in logs:
        ok = [e for e in episodes if e.run == str(log) and e.outcome == "success"]
        if ok and len(clean) < 10:
            clean.append(ok[0])
    print(f"{len(logs)} logs, {len(episodes)} episodes, {len(drops)} drops, {len(clean)} clean lifts")
    rows = [("drop", e, numbers(e)) for e in drops] + [("clean", e, numbers(e)) for e in clean]
    keys = list(rows[0][2])
    print("kind  episode                          " + " | ".join(keys))
    for kind, e, n in rows:
        print(f"{kind:5s} {e.label:33s} " + " | ".join(f"{n[k]:.1f}" for k in keys))
    for kind in ("drop", "clean"):
        sel = [n for k, _, n in rows if k == kind]
        print(kind, "median: " + " | ".join(f"{np.median([n[k] for n in sel]):.1f}" for k in keys))
    for e in drops:
        print(e.label, [ev["detail"] for ev in e.events])
    write_recording(drops + clean, load_robot(), save=out / "drops.rrd", name="sim2real-anchor-offset-drops")
    _plot(drops, clean, out / "lifts.png")
    return 0


def _plot(drops, clean, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(13, 4.2))
    for group, color in ((clean, "tab:green"), (drops, "tab:red")):
        for e in group:
            frames = lift(e)[:9]
            acting = [f for f in frames if f.q is not None]
            axes[0].plot(range(len(acting)), [f.vacuum_kpa for f in acting], color=color, alpha=0.7)
            axes[1].plot(range(len(frames)), [f.tcp[2] * 1e3 for f in frames], color=color, alpha=0.7)
            ahead = [(f.target[2] - f.tcp[2]) * 1e3 for f in acting if f.target is not None]
            axes[2].plot(range(len(ahead)), ahead, color=color, alpha=0.7)
    titles = (
        "vacuum level at each decision (kPa)",
        "TCP height (mm); a drop's last point: where the loss was found",
        "commanded target height above the TCP (mm)",
    )
    for ax, title in zip(axes, titles):
        ax.set_title(title, fontsize=9)
        ax.set_xlabel("decisions since the lift began (100 ms each)")
        ax.grid(alpha=0.3)
    axes[0].plot([], [], color="tab:red", label=f"{len(drops)} drops")
    axes[0].plot([], [], color="tab:green", label=f"{len(clean)} clean lifts")
    axes[0].legend()
    fig.suptitle(
        "sim2real-anchor-offset, conditions real_exact and real_hmd: the first 0.9 s of the lift, from the run logs"
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)


if __name__ == "__main__":
    sys.exit(main())
