"""Parity of the live annotation path: guided training with `mrguide annotate bot` over the wire vs the
in-process simulated annotator (same noise, same seeds).

    python benchmarks/live_parity.py [--seeds 3] [--steps 5000] [--out runs/live-parity]

For each seed it runs `mrguide train --stop-after STEPS` twice with configs/runs/live_parity.toml (σ = 1 cm):
once with the in-process annotator, once with `--expert live` answered by `mrguide annotate bot --noise
0.01 --seed S` over a loopback WebSocket. It compares the annotation logs (targets bit for bit), the
metrics and evaluation CSVs, and prints a table and, last, one JSON line.
"""

from __future__ import annotations

import argparse
import csv
import json
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CONFIG = ROOT / "configs" / "runs" / "live_parity.toml"
MRGUIDE = [sys.executable, "-m", "mrguide.cli"]


def train_local(out: Path, seed: int, steps: int) -> float:
    t = time.perf_counter()
    subprocess.run(
        MRGUIDE
        + [
            "train",
            "--config",
            str(CONFIG),
            "--seed",
            str(seed),
            "--stop-after",
            str(steps),
            "--quiet",
            "--out",
            str(out),
        ],
        check=True,
        capture_output=True,
        text=True,
    )
    return time.perf_counter() - t


def train_live(out: Path, seed: int, steps: int) -> float:
    t = time.perf_counter()
    proc = subprocess.Popen(
        MRGUIDE
        + [
            "train",
            "--config",
            str(CONFIG),
            "--seed",
            str(seed),
            "--stop-after",
            str(steps),
            "--quiet",
            "--expert",
            "live",
            "--port",
            "0",
            "--out",
            str(out),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    url = next(line.split(": ", 1)[1].strip() for line in proc.stdout if line.startswith("annotation page: "))
    bot = subprocess.run(
        MRGUIDE + ["annotate", "bot", "--url", url, "--noise", "0.01", "--seed", str(seed)],
        capture_output=True,
        text=True,
    )
    proc.wait()
    if proc.returncode or bot.returncode:
        raise RuntimeError(f"live run of seed {seed} failed: {proc.stderr.read()[-2000:]} {bot.stderr[-2000:]}")
    return time.perf_counter() - t


def read_csv(path: Path, drop: tuple[str, ...] = ("wall_s",)) -> list[dict]:
    with path.open() as fh:
        return [{k: v for k, v in r.items() if k not in drop} for r in csv.DictReader(fh)]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--steps", type=int, default=5000)
    ap.add_argument("--out", default=str(ROOT / "runs" / "live-parity"))
    args = ap.parse_args()
    out = Path(args.out)
    rows = []
    for seed in range(args.seeds):
        local, live = out / "local" / f"seed{seed}", out / "live" / f"seed{seed}"
        for d in (local, live):
            if d.exists():
                raise SystemExit(f"{d} exists: remove {out} to measure again")
        wall_local = train_local(local, seed, args.steps)
        wall_live = train_live(live, seed, args.steps)
        a = [json.loads(x) for x in (local / "annotations.jsonl").read_text().splitlines()]
        b = [json.loads(x) for x in (live / "annotations.jsonl").read_text().splitlines()]
        ev_a, ev_b = read_csv(local / "eval.csv"), read_csv(live / "eval.csv")
        rows.append(
            {
                "seed": seed,
                "annotations_local": len(a),
                "annotations_live": len(b),
                "targets_identical": [r["target"] for r in a] == [r["target"] for r in b],
                "remarks": sum(r["supersedes"] is not None for r in b),
                "metrics_identical": read_csv(local / "metrics.csv") == read_csv(live / "metrics.csv"),
                "eval_local": [float(r["success_rate"]) for r in ev_a],
                "eval_live": [float(r["success_rate"]) for r in ev_b],
                "latency_median_ms": round(1e3 * sorted(r["latency_s"] for r in b)[len(b) // 2], 2) if b else None,
                "wall_local_s": round(wall_local, 1),
                "wall_live_s": round(wall_live, 1),
            }
        )
        r = rows[-1]
        print(
            f"seed {seed}: annotations {r['annotations_local']} / {r['annotations_live']}, targets identical "
            f"{r['targets_identical']}, metrics identical {r['metrics_identical']}, eval local {r['eval_local']} live "
            f"{r['eval_live']}, answer latency median {r['latency_median_ms']} ms, wall {r['wall_local_s']} / {r['wall_live_s']} s",
            flush=True,
        )
    with (out / "parity.csv").open("w", newline="") as fh:
        w = csv.DictWriter(fh, list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    print(
        json.dumps(
            {
                "seeds": args.seeds,
                "steps": args.steps,
                "identical_runs": sum(r["targets_identical"] and r["metrics_identical"] for r in rows),
                "annotations": [r["annotations_live"] for r in rows],
                "remarks": [r["remarks"] for r in rows],
            }
        )
    )


if __name__ == "__main__":
    main()
