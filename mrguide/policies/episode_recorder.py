"""The per-step episode recorder of a training run (`mrguide train --record`): off by default.

Every training step (agent or expert) goes through `Trainer._env_step`; with a recorder attached, that step
is also kept here — the observation before it, the executed and the stored action, the reward, and what the
twin's arm, object and cup reached after it (read without noise and without drawing from any RNG, so a
recorded run trains exactly as an unrecorded one). Episodes are written whole, each as one gzip member of
`episodes.jsonl.gz` (so a crash loses at most the episode in flight), until the file reaches its size bound;
then one `{"kind": "truncated"}` record says where recording stopped and training goes on unrecorded.

Records (one JSON object per line):

- `{"kind": "header", "format": 1, "robot": ..., "joint_names": [...], "q_home": [...], "decision_period": ...}`
- `{"kind": "episode", "episode": <n>, "trainer_episode": ..., "type": "agent" | "expert", "goal": [...],
  "outcome": ..., "steps": [...]}`, each step `{"step", "t", "obs", "action", "stored", "reward", "zeta",
  "next_obs", "q", "object", "vacuum_kpa", "part", "g", "phase", "annotation"}` — `q`, `object`, `vacuum_kpa`
  and `part` after the step; `zeta` is what the replay buffer stored the step with (a demonstration's step
  counts as expert data only once its phase was completed, as the trainer decides); `annotation` is the
  annotations.jsonl record the expert followed (None for the agent).

A resumed run first cuts the file back to the episodes that ended at or before the checkpoint (they are not
run again; the later ones are).
"""

from __future__ import annotations

import gzip
import json
import logging
import os
import zlib
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from mrguide.task import OBS_PROGRESS, phase_from_progress

if TYPE_CHECKING:
    from mrguide.policies.train import Trainer

log = logging.getLogger(__name__)

FORMAT = 1
FILE_NAME = "episodes.jsonl.gz"
DEFAULT_LIMIT_MB = 256.0


def _floats(a: Any) -> list[float]:
    return [float(v) for v in np.asarray(a, dtype=float).ravel()]


def read_episodes(path: str | Path) -> tuple[dict, list[dict], bool]:
    """(header, episodes, truncated) of an `episodes.jsonl.gz`; a torn last member (a crash) is skipped."""
    path = Path(path)
    raw = path.read_bytes()
    try:
        text = gzip.decompress(raw).decode()
    except (EOFError, gzip.BadGzipFile, OSError):
        text = _whole_members(raw)
    header: dict = {}
    episodes: list[dict] = []
    truncated = False
    for line in text.splitlines():
        if not line.strip():
            continue
        rec = json.loads(line)
        kind = rec.get("kind")
        if kind == "header":
            header = rec
        elif kind == "episode":
            episodes.append(rec)
        elif kind == "truncated":
            truncated = True
    return header, episodes, truncated


def _whole_members(raw: bytes) -> str:
    """The text of the gzip members of `raw` that decompress whole (the last one may be torn)."""
    out: list[str] = []
    while raw:
        d = zlib.decompressobj(16 + zlib.MAX_WBITS)
        try:
            data = d.decompress(raw)
        except zlib.error:
            break
        if not d.eof:
            break
        out.append(data.decode())
        raw = d.unused_data
    return "".join(out)


class EpisodeRecorder:
    """Records a `Trainer`'s steps; attach with `trainer.recorder = EpisodeRecorder(...)` after any resume."""

    def __init__(self, trainer: Trainer, path: str | Path, limit_mb: float = DEFAULT_LIMIT_MB):
        self.path = Path(path)
        self.limit = int(limit_mb * 1024 * 1024)
        self.stopped = False
        self._open: dict | None = None
        self._key: tuple[int, str] | None = None
        self._pending: list[dict] = []  # a demonstration's steps whose ζ is not decided yet
        self._remarks = 0
        self.episodes = 0
        if trainer.counters.step > 0 and self.path.exists():
            self._cut_back(trainer.counters.step)
        elif not self.path.exists() or trainer.counters.step == 0:
            spec = trainer.env.robot_spec
            self._write(
                [
                    {
                        "kind": "header",
                        "format": FORMAT,
                        "robot": spec.name,
                        "joint_names": list(spec.joint_names),
                        "q_home": _floats(spec.q_home),
                        "decision_period": trainer.env.twin_cfg.decision_period,
                        "seed": trainer.cfg.seed,
                    }
                ],
                mode="wb",
            )

    # -- the hook ------------------------------------------------------------------------------------
    def step(self, trainer: Trainer, obs, action, stored, zeta, reward, next_obs, term, trunc, info) -> None:
        """One training step, as `Trainer._env_step` executed it (`zeta` None: a demonstration's step)."""
        if self.stopped:
            return
        kind = "agent" if zeta is not None else "expert"
        key = (trainer.counters.episode, kind)
        if key != self._key:
            self._finish()
            self._key = key
            self._remarks = trainer.counters.remarks
            self._open = {
                "kind": "episode",
                "episode": self.episodes,
                "trainer_episode": trainer.counters.episode,
                "type": kind,
                "goal": _floats(trainer.env.scene.goal),
                "outcome": None,
                "steps": [],
            }
        assert self._open is not None
        scene = trainer.env.scene
        record = {
            "step": trainer.counters.step + 1,
            "t": len(self._open["steps"]),
            "obs": _floats(obs),
            "action": _floats(action),
            "stored": _floats(action if stored is None else stored),
            "reward": float(reward),
            "zeta": 0 if zeta is not None else None,
            "next_obs": _floats(next_obs),
            "q": _floats(scene.joint_positions(noisy=False)),
            "object": _floats(scene.object_position()),
            "vacuum_kpa": max(0.0, -float(scene.suction.state.level)),
            "part": bool(info.get("part_present", False)),
            "g": 1 if trainer.env.vacuum else -1,
            "phase": int(phase_from_progress(obs[OBS_PROGRESS])),
            "annotation": trainer.expert.annotation_in_use(obs) if zeta is None else None,
        }
        if zeta is None:  # the trainer's rule (Trainer._expert_episode): a re-mark sends the held steps to ζ = 0
            if trainer.counters.remarks != self._remarks:
                self._decide(0)
                self._remarks = trainer.counters.remarks
            self._pending.append(record)
            if info.get("is_success") or phase_from_progress(next_obs[OBS_PROGRESS]) > phase_from_progress(
                obs[OBS_PROGRESS]
            ):
                self._decide(1)
        self._open["steps"].append(record)
        if term or trunc:
            self._open["outcome"] = info.get("outcome")
            self._finish()

    def close(self) -> None:
        """Write the episode in flight (the end of the run, an interrupt)."""
        self._finish()

    # -- writing -------------------------------------------------------------------------------------
    def _decide(self, zeta: int) -> None:
        for record in self._pending:
            record["zeta"] = zeta
        self._pending = []

    def _finish(self) -> None:
        if self._open is None:
            return
        self._decide(0)
        episode, self._open, self._key = self._open, None, None
        if not episode["steps"] or self.stopped:
            return
        member = gzip.compress((json.dumps(episode) + "\n").encode(), compresslevel=6)
        size = self.path.stat().st_size if self.path.exists() else 0
        if size + len(member) > self.limit:
            self.stopped = True
            marker = {"kind": "truncated", "at_step": episode["steps"][0]["step"] - 1, "limit_bytes": self.limit}
            self._write([marker])
            log.warning("episode recording stopped at step %d: %s reached its size bound", marker["at_step"], self.path)
            return
        with self.path.open("ab") as fh:
            fh.write(member)
            fh.flush()
            os.fsync(fh.fileno())
        self.episodes += 1

    def _write(self, records: list[dict], mode: str = "ab") -> None:
        data = gzip.compress("".join(json.dumps(r) + "\n" for r in records).encode())
        self.path.parent.mkdir(parents=True, exist_ok=True)
        with self.path.open(mode) as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())

    def _cut_back(self, step: int) -> None:
        """Resume: keep the header and the episodes that ended at or before `step` (a checkpoint's)."""
        header, episodes, _ = read_episodes(self.path)
        kept = [e for e in episodes if e["steps"][-1]["step"] <= step]
        tmp = self.path.with_name(self.path.name + ".tmp")
        with tmp.open("wb") as fh:
            fh.write(gzip.compress((json.dumps(header) + "\n").encode()))
            for e in kept:
                fh.write(gzip.compress((json.dumps(e) + "\n").encode()))
            fh.flush()
            os.fsync(fh.fileno())
        tmp.replace(self.path)
        self.episodes = len(kept)
