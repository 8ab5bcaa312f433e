"""Does pressing the cup deeper into the part before the lift cost grasps in the real cell? (phase_anchor drops)

The phase_anchor policies command their grasp target down to the workspace floor, 5.0 mm below the part's top,
in every lift we logged; the paper's actor 3.2 mm (median; `drops.py`). This probe runs the scripted expert in the dry-run real cell (configs/real_cell.toml: 12 mm compensator,
0.3 kg part, 25 N suction break force) with its grasp target centred on the part, the vacuum on, at a given
depth below the top, then the expert's lift, transport and release; it counts the outcomes per depth.

    python docs/results/sim2real-phase-anchor/press_lift_probe.py [--episodes 20]
"""

from __future__ import annotations

import argparse
import collections
import importlib.util
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[3]
sys.path.insert(0, str(ROOT))

from mrguide.config import load_section  # noqa: E402
from mrguide.deploy.runlog import RunLog  # noqa: E402
from mrguide.drivers.config import BusConfig, CobotBusConfig  # noqa: E402
from mrguide.twin.config import TwinConfig  # noqa: E402
from mrguide.twin.dry_run import dry_run  # noqa: E402
from mrguide.twin.env import EnvConfig  # noqa: E402

DEPTHS = (0.003, 0.005)  # m below the part's top: the paper's actor's median and the phase_anchor actor's


def press_probe():
    """docs/results/compliance/press_probe.py as a module: its pressing expert is the one used here."""
    spec = importlib.util.spec_from_file_location("press_probe", ROOT / "docs/results/compliance/press_probe.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--episodes", type=int, default=20)
    args = ap.parse_args()
    cfg = EnvConfig(twin=load_section(TwinConfig, ROOT / "configs" / "real_cell.toml", "twin"))
    expert = press_probe().pressing_expert

    def shift(depth: float) -> np.ndarray:  # from the part's centre to `depth` below its top
        return np.array([0.0, 0.0, 0.5 * cfg.task.object_height - depth])

    for depth in DEPTHS:
        bus = CobotBusConfig(bus=BusConfig(interface="virtual", channel=f"press-lift-{depth}"))
        with RunLog(Path("/tmp") / "press_lift_probe.jsonl", {"probe": depth}) as log:
            summary = dry_run(None, cfg, bus, args.episodes, 0, log, None, policy=expert(cfg, shift(depth), 1.0),
                              max_recoveries=args.episodes)
        outcomes = collections.Counter(e.outcome for e in summary.episodes)
        print(f"grasp target {depth * 1000:.0f} mm below the part's top: {dict(outcomes)}", flush=True)


if __name__ == "__main__":
    main()
