"""Pressing the cup into the part in the dry-run real cell, rigid vs on the 12 mm level-compensator.

The scripted expert runs each episode, except that its grasp phase drives the cup down to the workspace floor
(z = 0.045 m, 5 mm into the 5 cm part): centred with the vacuum off, or 14 mm off-centre with the vacuum on
(no seal: the sim-to-real EMCY 0x8611 case). Writes one row per episode to `press_probe.csv` beside this file.

    python docs/results/compliance/press_probe.py [--episodes 10]
"""

from __future__ import annotations

import argparse
import csv
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[3]
sys.path.insert(0, str(ROOT))

from mrguide.config import load_section  # noqa: E402
from mrguide.deploy.runlog import RunLog  # noqa: E402
from mrguide.drivers.config import BusConfig, CobotBusConfig  # noqa: E402
from mrguide.robot import load_robot  # noqa: E402
from mrguide.task import oracle_action, phase_from_progress  # noqa: E402
from mrguide.twin.config import CupConfig, TwinConfig  # noqa: E402
from mrguide.twin.dry_run import dry_run  # noqa: E402
from mrguide.twin.env import EnvConfig  # noqa: E402

CASES = {"centred, vacuum off": (0.0, -1.0), "14 mm off-centre, vacuum on": (0.014, 1.0)}


def pressing_expert(cfg: EnvConfig, shift: np.ndarray, vacuum: float):
    """The scripted expert, except that in the grasp phase it targets the part's centre + `shift` (m) with
    the vacuum command `vacuum` (a target below the box floor is clamped to it, z = 0.045)."""
    ws = load_robot(cfg.robot).workspace

    def policy(obs):
        if phase_from_progress(obs[4]) != 1:
            return oracle_action(obs, cfg.task, ws.to_normalized).astype(np.float32)
        target = np.asarray(obs[5:8], float) + shift
        return np.concatenate([ws.to_normalized(target), [vacuum]]).astype(np.float32)

    return policy


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=10)
    args = ap.parse_args()
    real = load_section(TwinConfig, ROOT / "configs" / "real_cell.toml", "twin")
    rows = []
    for stroke in (0.0, real.cup.stroke):
        cfg = EnvConfig(twin=replace(real, cup=CupConfig(stroke=stroke)))
        for case, (offset, vacuum) in CASES.items():
            bus = CobotBusConfig(bus=BusConfig(interface="virtual", channel=f"press-{stroke}-{offset}"))
            with RunLog(Path("/tmp") / "press_probe.jsonl", {"probe": case}) as log:
                summary = dry_run(
                    None,
                    cfg,
                    bus,
                    args.episodes,
                    0,
                    log,
                    None,
                    policy=pressing_expert(cfg, np.array([offset, 0.0, 0.0]), vacuum),
                    max_recoveries=args.episodes,
                )
            for e in summary.episodes:
                safety = ";".join(sorted(k for k in e.events if k != "workspace"))
                rows.append(
                    {
                        "stroke_m": stroke,
                        "case": case,
                        "episode": e.index,
                        "outcome": e.outcome,
                        "safety_events": safety,
                    }
                )
            stops = sum(e.outcome == "safety_stop" for e in summary.episodes)
            print(f"stroke {stroke * 1000:.0f} mm | {case}: {stops}/{len(summary.episodes)} safety stops", flush=True)
    with (Path(__file__).parent / "press_probe.csv").open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


if __name__ == "__main__":
    main()
