"""Pressing the cup into the part in the dry-run real cell, rigid vs on its level-compensator (docs/sim2real.md).

The scripted expert runs each episode, except that its grasp phase drives the cup down to the workspace floor
(z = 0.045 m, 5 mm into the 5 cm part): centred with the vacuum off, or 14 mm off-centre with the vacuum on
(no seal: the sim-to-real EMCY 0x8611 case). Prints one line per case and writes one row per episode to
OUT/press_probe.csv.

    python tools/press_probe.py [--episodes 10] [--cell configs/cells/real_cell.toml] [--out docs/results/compliance]
"""

from __future__ import annotations

import argparse
import csv
import tempfile
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np

from mrguide.cell.config import CellConfig
from mrguide.cell.dry_run import dry_run
from mrguide.cell_layout import CupConfig
from mrguide.config import load_section
from mrguide.deploy.runlog import RunLog
from mrguide.drivers.config import BusConfig, CobotBusConfig
from mrguide.robot import load_robot
from mrguide.task import OBS_OBJECT, OBS_PROGRESS, Phase, oracle_action, phase_from_progress
from mrguide.twin.config import TwinConfig
from mrguide.twin.env import EnvConfig

#: case -> (offset of the cup from the part's centre in x (m), vacuum command)
CASES = {"centred, vacuum off": (0.0, -1.0), "14 mm off-centre, vacuum on": (0.014, 1.0)}


def pressing_expert(cfg: EnvConfig, shift: np.ndarray, vacuum: float) -> Callable[[np.ndarray], np.ndarray]:
    """The scripted expert, except that in the grasp phase it targets the part's centre + `shift` (m) with
    the vacuum command `vacuum` (a target below the box floor is clamped to it, z = 0.045)."""
    ws = load_robot(cfg.robot).workspace

    def policy(obs: np.ndarray) -> np.ndarray:
        if phase_from_progress(obs[OBS_PROGRESS]) != Phase.GRASP:
            return oracle_action(obs, cfg.task, ws.to_normalized).astype(np.float32)
        target = np.asarray(obs[OBS_OBJECT], float) + shift
        return np.concatenate([ws.to_normalized(target), [vacuum]]).astype(np.float32)

    return policy


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--episodes", type=int, default=10)
    ap.add_argument("--cell", default="configs/cells/real_cell.toml", help="the cell config whose [twin] is pressed")
    ap.add_argument("--out", default="docs/results/compliance", help="directory for press_probe.csv")
    args = ap.parse_args(argv)
    real = load_section(TwinConfig, Path(args.cell), "twin")
    rows = []
    with tempfile.TemporaryDirectory() as scratch:
        for stroke in (0.0, real.cup.stroke):
            cfg = CellConfig().with_twin(replace(real, cup=CupConfig(stroke=stroke)))
            for case, (offset, vacuum) in CASES.items():
                bus = CobotBusConfig(bus=BusConfig(interface="virtual", channel=f"press-{stroke}-{offset}"))
                with RunLog(Path(scratch) / "press_probe.jsonl", {"probe": case}) as log:
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
                print(
                    f"stroke {stroke * 1000:.0f} mm | {case}: {stops}/{len(summary.episodes)} safety stops", flush=True
                )
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    with (out / "press_probe.csv").open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
