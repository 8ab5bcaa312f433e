"""Count a sweep's drive-fault events by swept value and by the task phase of the decision before them.

    python docs/results/sim2real-sweeps/fault_phases.py DIR   (DIR holds the sweep's gzipped run logs)
"""

from __future__ import annotations

import gzip
import json
import re
import sys
from collections import Counter
from pathlib import Path


def main(folder: Path) -> None:
    counts: Counter[tuple[str, str]] = Counter()
    for path in sorted(folder.glob("log-*.jsonl.gz")):
        value = re.search(r"-(\d+(?:\.\d+)?)-seed", path.name).group(1)
        phase = "before the first decision"
        with gzip.open(path, "rt") as fh:
            for line in fh:
                record = json.loads(line)
                if record["kind"] == "episode_start":
                    phase = "before the first decision"
                elif record["kind"] == "decision":
                    phase = f"phase {record['phase']}"
                elif record["kind"] == "safety" and record.get("event") == "drive_fault":
                    counts[(value, phase)] += 1
    for (value, phase), n in sorted(counts.items()):
        print(f"{value}: {n} drive fault(s) {phase}")


if __name__ == "__main__":
    main(Path(sys.argv[1]))
