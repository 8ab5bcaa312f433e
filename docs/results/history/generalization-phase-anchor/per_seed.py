"""Success per seed near the training goal region (0-0.03 m) and far from it (0.18-0.21 m), from each seed's
goals.csv (the report's bins: a target belongs to [low, high), the last bin also takes max_distance itself).

    python docs/results/generalization-phase-anchor/per_seed.py [DIR ...]
"""
import csv
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent


def share(rows: list[dict[str, str]], low: float, high: float, last: bool) -> str:
    sel = [r for r in rows if low <= float(r["distance_m"]) < high or (last and float(r["distance_m"]) == high)]
    return f"{100 * sum(int(r['successes']) for r in sel) / sum(int(r['episodes']) for r in sel):.0f} %"


for root in [Path(a) for a in sys.argv[1:]] or [HERE]:
    for seed in sorted((root / "guided").glob("seed*"), key=lambda p: int(p.name[4:])):
        rows = list(csv.DictReader(open(seed / "goals.csv")))
        print(f"{root.name} {seed.name}: near {share(rows, 0.0, 0.03, False)}, far {share(rows, 0.18, 0.21, True)}")
