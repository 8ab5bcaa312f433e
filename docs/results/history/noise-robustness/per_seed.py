"""Per σ of a noise-robustness experiment directory: each seed's best and final evaluation success and its
re-marks (from the runs' eval.csv and metrics.csv), the ranges the README quotes.

    python docs/results/noise-robustness/per_seed.py [DIR]   (default: this directory; also the probe directories)
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path


def main(root: Path) -> None:
    for sigma_dir in sorted(root.glob("sigma_*")):
        best, final, remarks = [], [], []
        for run in sorted(sigma_dir.glob("seed*")):
            evals = [float(r["success_rate"]) for r in csv.DictReader((run / "eval.csv").open())]
            rows = list(csv.DictReader((run / "metrics.csv").open()))
            best.append(max(evals))
            final.append(evals[-1])
            remarks.append(int(rows[-1]["remarks"]))
        pct = lambda xs: f"{100 * min(xs):.0f}–{100 * max(xs):.0f} %"  # noqa: E731
        print(f"{sigma_dir.name}: {len(best)} seeds; best evaluation {pct(best)}; final {pct(final)}; "
              f"re-marks {min(remarks)}–{max(remarks)}")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parent)
