"""The drops of conditions 2 and 3 (real_exact, real_hmd) in the sim-to-real run logs, and how the grasp and
lift of a set of policies look. For each directory given (default: this one and ../sim2real-v4-compliance, the
paper's actor at 20k steps), over every episode that reached the lift:
- the vacuum and the cup's offset from the part's centre (larger of x/y) at the first lift decision;
- the TCP's height above the part's top when the policy first commanded the vacuum on in the grasp phase;
- the largest lateral distance of a lift decision's target from the TCP;
- how far below the part's top the grasp phase's deepest target lay;
and for the first directory each dropped episode's offset, vacuum, deepest grasp target and largest lateral lift command.

    python docs/results/sim2real-phase-anchor/drops.py [DIR ...]
"""
import gzip
import json
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
HALF_HEIGHT = 0.025  # m, half the 5 cm cube (TaskConfig.object_height)


def episodes(log: Path) -> tuple[dict[int, list[dict]], dict[int, str]]:
    rows = [json.loads(line) for line in gzip.open(log, "rt")]
    decisions: dict[int, list[dict]] = {}
    for r in rows:
        if r["kind"] == "decision" and r.get("episode") is not None:
            decisions.setdefault(r["episode"], []).append(r)
    return decisions, {r["episode"]: r.get("outcome") for r in rows if r["kind"] == "episode_end"}


def summarize(root: Path, list_drops: bool) -> None:
    vac, off, switch, lateral, depth = [], [], [], [], []
    for log in sorted(root.glob("**/sim2real/log-real_*.jsonl.gz")):
        decisions, outcome = episodes(log)
        for ep, rs in decisions.items():
            lift = [r for r in rs if r["phase"] == 2]
            if not lift:
                continue
            o = np.array(lift[0]["obs"])
            vac.append(lift[0]["vacuum_kpa"])
            off.append(1000 * np.abs(o[:2] - o[5:7]).max())
            grasp = [r for r in rs if r["phase"] == 1]
            top = grasp[0]["obs"][7] + HALF_HEIGHT if grasp else np.nan  # the part's top as the grasp phase began
            depth.append(1000 * (top - min(r["target"][2] for r in grasp)) if grasp else np.nan)
            on = [r for r in grasp if r["action"][3] > 0]
            if on:
                switch.append(1000 * (on[0]["obs"][2] - on[0]["obs"][7] - HALF_HEIGHT))
            lateral.append(max(1000 * np.linalg.norm(np.subtract(r["target"][:2], r["obs"][:2])) for r in lift))
            if list_drops and outcome.get(ep) == "dropped":
                print(f"  drop: {log.relative_to(root)} episode {ep}: offset {off[-1]:.0f} mm, vacuum {vac[-1]:.0f} kPa, "
                      f"deepest grasp target {depth[-1]:.1f} mm, lateral lift command up to {lateral[-1]:.0f} mm")
    print(f"{root.name}: {len(vac)} lifts; vacuum at the first lift decision median {np.median(vac):.0f} kPa "
          f"(p10 {np.percentile(vac, 10):.0f}); cup offset median {np.median(off):.1f} mm (p90 {np.percentile(off, 90):.1f}); "
          f"vacuum switched on {np.median(switch):.0f} mm above the part (median); lateral lift command "
          f"median {np.median(lateral):.0f} mm (p90 {np.percentile(lateral, 90):.0f}); deepest grasp target "
          f"{np.nanmedian(depth):.1f} mm below the part's top (median; range {np.nanmin(depth):.1f}-{np.nanmax(depth):.1f})")


if __name__ == "__main__":
    roots = [Path(a) for a in sys.argv[1:]] or [HERE, HERE.parent / "sim2real-v4-compliance"]
    for i, root in enumerate(roots):
        summarize(root, list_drops=i == 0)
