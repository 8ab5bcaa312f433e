"""`mrguide export lerobot`: a training run's demonstrations (or all its recorded episodes) as a LeRobot dataset
in the v3.0 on-disk format, written with pyarrow alone (no torch, no `datasets`, no `lerobot`: it runs where
mrguide's robot-PC profile runs).

The layout and files follow huggingface/lerobot's writer (src/lerobot/datasets: utils.py, dataset_metadata.py,
dataset_writer.py, compute_stats.py; CODEBASE_VERSION "v3.0"):

    meta/info.json                                  codebase_version, fps, features, totals, path templates
    meta/stats.json                                 per feature: min, max, mean, std, count, q01 q10 q50 q90 q99
    meta/tasks.parquet                              task_index, indexed by the task text (pandas index "task")
    meta/episodes/chunk-000/file-000.parquet        one row per episode: episode_index, tasks, length,
                                                    data/chunk_index, data/file_index, dataset_from_index,
                                                    dataset_to_index, meta/episodes/chunk_index and file_index,
                                                    stats/<feature>/<stat>
    data/chunk-000/file-000.parquet                 one row per frame, one row group per episode

A frame is one training step: `observation.state` the observation before it (11 numbers, task.OBS_LAYOUT),
`action` the action stored for it (the label the learner clones: with guidance.action_noise, not the executed
one), `phase`, `zeta` (1: the replay buffer kept the step as expert data), `expert` (1: a demonstration's step,
whatever its ζ), and the annotation the expert followed: `annotation.id` (its annotations.jsonl record; -1 for
none), `annotation.source` ("oracle", "simulated", "file", "live"; "" for none) and `annotation.latency_s` (-1 where the
source reports none: only a live person's answers have a latency). No camera frames are recorded in training, so the dataset has no video features.
Quantiles in stats.json are exact (numpy), where lerobot's writer estimates them from histograms.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from mrguide.errors import InputError
from mrguide.task import ACT_LAYOUT, OBS_LAYOUT

CODEBASE_VERSION = "v3.0"
CHUNK = "chunk-000/file-000"
QUANTILES = (0.01, 0.10, 0.50, 0.90, 0.99)


class ExportError(InputError):
    """A run that cannot be exported (not recorded, no demonstrations), or an output directory in the way."""


def features() -> dict[str, dict]:
    """The dataset's features, as meta/info.json lists them (LeRobot dtype, shape, names)."""
    scalar = {"shape": [1], "names": None}
    return {
        "observation.state": {"dtype": "float32", "shape": [len(OBS_LAYOUT)], "names": list(OBS_LAYOUT)},
        "action": {"dtype": "float32", "shape": [len(ACT_LAYOUT)], "names": list(ACT_LAYOUT)},
        "phase": {"dtype": "int64", **scalar},
        "zeta": {"dtype": "int64", **scalar},
        "expert": {"dtype": "int64", **scalar},
        "annotation.id": {"dtype": "int64", **scalar},
        "annotation.source": {"dtype": "string", **scalar},
        "annotation.latency_s": {"dtype": "float32", **scalar},
        "timestamp": {"dtype": "float32", **scalar},
        "frame_index": {"dtype": "int64", **scalar},
        "episode_index": {"dtype": "int64", **scalar},
        "index": {"dtype": "int64", **scalar},
        "task_index": {"dtype": "int64", **scalar},
    }


def _annotations(path: Path) -> dict[int, dict]:
    """annotations.jsonl by record id."""
    if not path.is_file():
        return {}
    out = {}
    for line in path.read_text().splitlines():
        if line.strip():
            rec = json.loads(line)
            out[int(rec["id"])] = rec
    return out


def _stats(values: np.ndarray) -> dict[str, list]:
    v = values.reshape(len(values), -1).astype(np.float64)
    out = {
        "min": v.min(axis=0),
        "max": v.max(axis=0),
        "mean": v.mean(axis=0),
        "std": v.std(axis=0),
        "count": np.array([len(values)]),
    }
    for q in QUANTILES:
        out[f"q{int(q * 100):02d}"] = np.quantile(v, q, axis=0)
    return {k: np.asarray(x).tolist() for k, x in out.items()}


def export_lerobot(run: Path, out: Path, all_episodes: bool = False, task: str = "pick and place") -> str:
    """Write the dataset; returns a one-paragraph summary."""
    run_dir, header, chosen, truncated = _chosen_episodes(run, out, all_episodes)
    annotations = _annotations(run_dir / "annotations.jsonl")
    fps = round(1.0 / float(header.get("decision_period") or 0.1))
    cols, bounds = _frame_columns(chosen, annotations, fps)
    table = _frame_table(cols)

    tmp = out.with_name(out.name + ".tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    _write_frames(tmp / "data" / f"{CHUNK}.parquet", table, bounds)

    numeric = [n for n, ft in features().items() if ft["dtype"] != "string"]
    stacked = {n: np.array(cols[n], dtype=np.float64) for n in numeric}
    ep_cols = _episode_columns(chosen, bounds, task, stacked)
    episodes_path = tmp / "meta" / "episodes" / f"{CHUNK}.parquet"
    episodes_path.parent.mkdir(parents=True)
    pq.write_table(pa.table(ep_cols), episodes_path, compression="snappy")
    _write_tasks(pa, pq, tmp / "meta" / "tasks.parquet", [task])
    stats = {n: _stats(stacked[n]) for n in numeric}
    (tmp / "meta" / "stats.json").write_text(json.dumps(stats, indent=4))
    info = _info(header, fps, len(chosen), len(cols["index"]))
    (tmp / "meta" / "info.json").write_text(json.dumps(info, indent=4))
    if out.exists():
        out.rmdir()
    tmp.replace(out)
    demos = sum(e["type"] == "expert" for e in chosen)
    return (
        f"LeRobot dataset ({CODEBASE_VERSION}) at {out}: {len(chosen)} episodes ({demos} demonstrations), "
        f"{len(cols['index'])} frames at {fps} fps, task {task!r}; no camera frames were recorded, so no videos"
        + ("; the recording was cut at its size bound, so later episodes are missing" if truncated else "")
    )


def _chosen_episodes(run: Path, out: Path, all_episodes: bool) -> tuple[Path, dict, list[dict], bool]:
    """(run directory, recording header, episodes to export, truncated); ExportError if there is nothing to export
    or `out` is in the way."""
    from mrguide.policies.episode_recorder import FILE_NAME, read_episodes

    recorded = run / FILE_NAME if run.is_dir() else run
    if not recorded.is_file():
        raise ExportError(f"{run}: no {FILE_NAME}: record the training run with `mrguide train --record`")
    run_dir = recorded.parent
    if out.exists() and any(out.iterdir()):
        raise ExportError(f"--out {out}: exists and is not empty")
    header, episodes, truncated = read_episodes(recorded)
    chosen = [e for e in episodes if all_episodes or e["type"] == "expert"]
    if not chosen:
        raise ExportError(f"{recorded}: no {'recorded episode' if all_episodes else 'demonstration'} to export")
    return run_dir, header, chosen, truncated


def _frame_columns(
    chosen: list[dict], annotations: dict[int, dict], fps: int
) -> tuple[dict[str, list], list[tuple[int, int]]]:
    """The frames' values per feature, and each episode's (first, end) frame index."""
    cols: dict[str, list] = {k: [] for k in features()}
    bounds = []
    for k, ep in enumerate(chosen):
        start = len(cols["index"])
        for t, s in enumerate(ep["steps"]):
            ann = annotations.get(s["annotation"]) if s.get("annotation") is not None else None
            cols["observation.state"].append(s["obs"])
            cols["action"].append(s["stored"])
            cols["phase"].append(s["phase"])
            cols["zeta"].append(int(s["zeta"] or 0))
            cols["expert"].append(int(ep["type"] == "expert"))
            cols["annotation.id"].append(-1 if s.get("annotation") is None else int(s["annotation"]))
            cols["annotation.source"].append(ann["source"] if ann else "")
            latency = ann.get("latency_s") if ann else None
            cols["annotation.latency_s"].append(-1.0 if latency is None else float(latency))
            cols["timestamp"].append(t / fps)
            cols["frame_index"].append(t)
            cols["episode_index"].append(k)
            cols["index"].append(start + t)
            cols["task_index"].append(0)
        bounds.append((start, len(cols["index"])))
    return cols, bounds


def _frame_table(cols: dict[str, list]) -> pa.Table:
    """The frame columns as an arrow table with the features' types."""
    schema = {
        "observation.state": pa.list_(pa.float32(), len(OBS_LAYOUT)),
        "action": pa.list_(pa.float32(), len(ACT_LAYOUT)),
        "annotation.source": pa.string(),
    }
    arrays = {}
    for name, ft in features().items():
        typ = schema.get(name) or (pa.float32() if ft["dtype"] == "float32" else pa.int64())
        arrays[name] = pa.array(cols[name], type=typ)
    return pa.table(arrays)


def _write_frames(data: Path, table: pa.Table, bounds: list[tuple[int, int]]) -> None:
    """The data parquet file at `data`, one row group per episode."""
    data.parent.mkdir(parents=True)
    with pq.ParquetWriter(data, table.schema, compression="snappy") as writer:
        for a, b in bounds:  # one row group per episode, as lerobot writes them
            writer.write_table(table.slice(a, b - a))


def _episode_columns(
    chosen: list[dict], bounds: list[tuple[int, int]], task: str, stacked: dict[str, np.ndarray]
) -> dict[str, list]:
    """meta/episodes' columns: one row per episode, with its per-feature stats over the `stacked` features."""
    ep_cols: dict[str, list] = {
        "episode_index": list(range(len(chosen))),
        "tasks": [[task] for _ in chosen],
        "length": [b - a for a, b in bounds],
        "data/chunk_index": [0] * len(chosen),
        "data/file_index": [0] * len(chosen),
        "dataset_from_index": [a for a, _ in bounds],
        "dataset_to_index": [b for _, b in bounds],
        "meta/episodes/chunk_index": [0] * len(chosen),
        "meta/episodes/file_index": [0] * len(chosen),
        # ours: where each episode came from in the training run
        "mrguide/type": [e["type"] for e in chosen],
        "mrguide/trainer_episode": [int(e["trainer_episode"]) for e in chosen],
        "mrguide/outcome": [e["outcome"] or "" for e in chosen],
        "mrguide/first_step": [int(e["steps"][0]["step"]) for e in chosen],
    }
    per_episode = [{n: _stats(values[a:b]) for n, values in stacked.items()} for a, b in bounds]
    for n in stacked:
        for stat in per_episode[0][n]:
            ep_cols[f"stats/{n}/{stat}"] = [s[n][stat] for s in per_episode]
    return ep_cols


def _info(header: dict, fps: int, total_episodes: int, total_frames: int) -> dict:
    """meta/info.json's content."""
    return {
        "codebase_version": CODEBASE_VERSION,
        "fps": fps,
        "features": features(),
        "total_episodes": total_episodes,
        "total_frames": total_frames,
        "total_tasks": 1,
        "chunks_size": 1000,
        "data_files_size_in_mb": 100,
        "video_files_size_in_mb": 200,
        "data_path": "data/chunk-{chunk_index:03d}/file-{file_index:03d}.parquet",
        "video_path": None,
        "robot_type": header.get("robot"),
        "splits": {"train": f"0:{total_episodes}"},
    }


def _write_tasks(pa, pq, path: Path, tasks: list[str]) -> None:
    """meta/tasks.parquet as pandas writes a DataFrame indexed by "task" (lerobot reads it with pd.read_parquet and
    looks tasks up by that index), with the pandas schema metadata written by hand: pandas is not needed here."""
    table = pa.table({"task_index": pa.array(range(len(tasks)), pa.int64()), "task": pa.array(tasks, pa.string())})
    pandas_meta = {
        "index_columns": ["task"],
        "column_indexes": [
            {
                "name": None,
                "field_name": None,
                "pandas_type": "unicode",
                "numpy_type": "object",
                "metadata": {"encoding": "UTF-8"},
            }
        ],
        "columns": [
            {
                "name": "task_index",
                "field_name": "task_index",
                "pandas_type": "int64",
                "numpy_type": "int64",
                "metadata": None,
            },
            {"name": "task", "field_name": "task", "pandas_type": "unicode", "numpy_type": "object", "metadata": None},
        ],
        "creator": {"library": "pyarrow", "version": pa.__version__},
        "pandas_version": "2.2.3",
    }
    table = table.replace_schema_metadata({b"pandas": json.dumps(pandas_meta).encode()})
    pq.write_table(table, path)
