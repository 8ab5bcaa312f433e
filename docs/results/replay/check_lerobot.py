"""Check a dataset written by `mrguide export lerobot` with huggingface lerobot's own reader.

Run it in the lerobot venv (not mrguide's: lerobot needs torch, datasets, torchvision; the recipe is at the top of
check_lerobot.txt beside this file), offline, on the local directory:

    HF_HUB_OFFLINE=1 /tmp/lrcheck/venv/bin/python docs/results/replay/check_lerobot.py DIR [DIR ...]

It loads DIR with LeRobotDataset (root=DIR), prints what the reader sees, checks every frame it returns against the
data parquet read with pyarrow, `dataset.meta` against meta/*, and a subset and an action-chunk load against
the episode bounds (and a torch DataLoader batch of it). Exit status 1 on any mismatch.
"""

import json
import os
import sys
from pathlib import Path

os.environ.setdefault("HF_HUB_OFFLINE", "1")

import lerobot
import numpy as np
import pyarrow.parquet as pq
import torch
from lerobot.datasets.lerobot_dataset import LeRobotDataset

KEYS = ("observation.state", "action", "phase", "zeta", "episode_index", "frame_index", "index")


def check(root: Path) -> list[str]:
    bad: list[str] = []
    ds = LeRobotDataset("mrguide/local", root=root)
    info = json.loads((root / "meta/info.json").read_text())
    print(f"== {root}\nnum_episodes {ds.num_episodes}  num_frames {ds.num_frames}  fps {ds.fps}  len {len(ds)}")
    for name, ft in ds.features.items():
        print(f"  {name:22s} {ft['dtype']:8s} {tuple(ft['shape'])}  {ft.get('names')}")

    m = ds.meta  # meta against meta/info.json, episodes parquet, stats.json, tasks
    for key in ("codebase_version", "fps", "total_episodes", "total_frames", "total_tasks", "robot_type",
                "chunks_size", "data_path", "video_path"):  # fmt: skip
        if m.info[key] != info[key]:
            bad.append(f"meta.info[{key}] {m.info[key]!r} != info.json {info[key]!r}")
    feats = {k: {**v, "shape": list(v["shape"])} for k, v in m.features.items()}
    if feats != info["features"]:
        bad.append("meta.features != info.json features")
    if (ds.num_episodes, ds.num_frames, ds.fps) != (info["total_episodes"], info["total_frames"], info["fps"]):
        bad.append("num_episodes / num_frames / fps != info.json")
    if m.video_keys or m.image_keys:
        bad.append(f"camera keys {m.camera_keys}: none were written")
    rows = pq.read_table(root / "data/chunk-000/file-000.parquet").to_pylist()
    eps = pq.read_table(root / "meta/episodes/chunk-000/file-000.parquet").to_pylist()
    ends: dict[int, int] = {}  # each episode's bounds, from the data rows themselves
    for r in rows:
        ends[r["episode_index"]] = r["index"] + 1
    for k, e in enumerate(eps):
        got, n = m.episodes[k], sum(r["episode_index"] == k for r in rows)
        bounds = {"episode_index": k, "length": n, "dataset_from_index": ends.get(k, 0) - n}
        for key, want in {**e, **bounds, "dataset_to_index": ends.get(k)}.items():
            if key in got and got[key] != want:
                bad.append(f"meta.episodes[{k}][{key}] {got[key]!r} != {want!r}")
    if len(eps) != len(m.episodes) or sorted(ends) != list(range(len(eps))):
        bad.append(f"{len(m.episodes)} episodes in meta, {len(eps)} in the parquet, {len(ends)} in the data")
    stats = json.loads((root / "meta/stats.json").read_text())
    for name, st in stats.items():
        for s, v in st.items():
            if not np.array_equal(np.asarray(m.stats[name][s]), np.asarray(v)):
                bad.append(f"meta.stats[{name}][{s}] != stats.json")
    print(f"tasks {list(m.tasks.index)} -> {list(m.tasks['task_index'])}")

    if len(rows) != len(ds):  # every frame against the parquet
        bad.append(f"len(dataset) {len(ds)} != parquet rows {len(rows)}")
    for i, row in enumerate(rows[: len(ds)]):
        item, e = ds[i], m.episodes[row["episode_index"]]
        if (
            row["index"] != i
            or row["frame_index"] != i - e["dataset_from_index"]
            or row["timestamp"] != np.float32(row["frame_index"] / ds.fps)
        ):
            bad.append(f"parquet row {i}: index {row['index']}, frame_index {row['frame_index']}, {row['timestamp']}")
        for key in KEYS:
            want = torch.tensor(row[key], dtype=item[key].dtype)
            if item[key].shape != want.shape or not torch.equal(item[key], want):
                bad.append(f"frame {i} {key}: {item[key].tolist()} != parquet {row[key]}")
        if item["task"] != m.tasks.index[row["task_index"]]:
            bad.append(f"frame {i} task {item['task']!r}")
    print(f"checked {min(len(rows), len(ds))} frames x {KEYS} + task")

    last = len(eps) - 1  # a subset of episodes, with action chunks padded at the episode's end
    sub = LeRobotDataset("mrguide/local", root=root, episodes=[0, last], delta_timestamps={"action": [0, 1 / ds.fps]})
    want_rows = [r for r in rows if r["episode_index"] in (0, last)]
    if len(sub) != len(want_rows):
        bad.append(f"episodes=[0, {last}]: {len(sub)} frames != {len(want_rows)}")
    for j, row in enumerate(want_rows[: len(sub)]):
        item, end = sub[j], ends[row["episode_index"]]
        pad = row["index"] + 1 >= end
        nxt = rows[min(row["index"] + 1, end - 1)]["action"]
        want = torch.tensor([row["action"], nxt], dtype=torch.float32)
        if item["index"] != row["index"] or not torch.equal(item["action"], want) or item["action_is_pad"][1] != pad:
            bad.append(f"episodes=[0, {last}] item {j} (index {row['index']}): action chunk or padding differs")
    batch = next(iter(torch.utils.data.DataLoader(sub, batch_size=8, shuffle=True)))  # as a training loop reads it
    if batch["action"].shape != (8, 2, len(ds.features["action"]["names"])) or len(batch["annotation.source"]) != 8:
        bad.append(f"DataLoader batch: action {tuple(batch['action'].shape)}")
    print(f"subset episodes [0, {last}]: {len(sub)} frames; 2-step action chunks, padding, DataLoader batch ok")
    return bad


def main() -> int:
    print(f"lerobot {lerobot.__version__}  torch {torch.__version__}")
    failed = False
    for arg in sys.argv[1:]:
        bad = check(Path(arg))
        for b in bad[:20]:
            print("MISMATCH", b)
        print(f"{arg}: {'FAIL, ' + str(len(bad)) + ' mismatches' if bad else 'OK'}\n")
        failed |= bool(bad)
    return 1 if failed or len(sys.argv) < 2 else 0


if __name__ == "__main__":
    sys.exit(main())
