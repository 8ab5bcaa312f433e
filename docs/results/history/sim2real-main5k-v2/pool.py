"""Pool the per-policy sim-to-real tables of a directory (DIR/seed*/sim2real/sim2real.csv; default this one):
success per condition over all training seeds, 95 % Wilson interval, failure counts. Writes DIR/pooled.csv and
prints it as markdown.

    python docs/results/sim2real-main5k-v2/pool.py [DIR]
"""

from __future__ import annotations

import csv
import sys
from collections import defaultdict
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parents[2]))

from mrguide.experiments.stats import wilson  # noqa: E402

FAILURES = ("no_grasp", "dropped", "misplaced", "knocked_off", "timeout", "safety_stop")


def main(root: Path) -> None:
    totals: dict[str, dict[str, float]] = defaultdict(lambda: defaultdict(float))
    for table in sorted(root.glob("seed*/sim2real/sim2real.csv")):
        for row in csv.DictReader(table.open()):
            t = totals[row["condition"]]
            t["episodes"] += int(row["episodes"])
            t["success"] += round(float(row["success_rate"]) * int(row["episodes"]))
            for k in FAILURES:
                t[k] += int(row[k])
    rows = []
    for cond, t in totals.items():
        low, high = wilson(int(t["success"]), int(t["episodes"]))
        rows.append({"condition": cond, "episodes": int(t["episodes"]), "success": int(t["success"]),
                     "rate": round(t["success"] / t["episodes"], 4), "ci_low": round(low, 4), "ci_high": round(high, 4),
                     **{k: int(t[k]) for k in FAILURES}})
    with (root / "pooled.csv").open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    print("| condition | success | 95 % CI | " + " | ".join(FAILURES) + " |")
    print("| --- " * (3 + len(FAILURES)) + "|")
    for r in rows:
        print(f"| {r['condition']} | {r['success']}/{r['episodes']} = {100 * r['rate']:.0f} % | "
              f"{100 * r['ci_low']:.0f}–{100 * r['ci_high']:.0f} % | " + " | ".join(str(r[k]) for k in FAILURES) + " |")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else HERE)
