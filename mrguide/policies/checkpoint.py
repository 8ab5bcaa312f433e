"""Checkpoint files: a header with the format and a SHA-256 digest of the torch payload, written atomically.

    MRGUIDE-CHECKPOINT <format> <sha256 hex>\\n<torch.save bytes>

A flipped byte anywhere in the payload, a truncated file, another format or another program's file is
refused with CheckpointError before torch unpickles anything.
"""

from __future__ import annotations

import hashlib
import io
import os
from pathlib import Path
from typing import Any

import torch

from mrguide.errors import InputError

MAGIC = b"MRGUIDE-CHECKPOINT"
FORMAT = 6  # 2: critics as one ensemble; 3: update counter; 4: evaluation counter; 5: digest header, re-marks;
# 6: the 0.2 learner (anchored actor, LayerNorm critics, the SAC peer)
REQUIRED = (
    "config",
    "agent",
    "agent_pool",
    "expert_pool",
    "rng",
    "torch_rng",
    "annotator_rng",
    "expert_noise_rng",
    "counters",
)


class CheckpointError(InputError):
    """A checkpoint that is missing, corrupt, of another format, or of another configuration."""


def write_checkpoint(path: Path, state: dict[str, Any]) -> Path:
    """Write `state` (plus the format) to `path` via a temporary file and a rename; fsync'd."""
    buf = io.BytesIO()
    torch.save({**state, "format": FORMAT}, buf)
    payload = buf.getvalue()
    header = MAGIC + b" %d %s\n" % (FORMAT, hashlib.sha256(payload).hexdigest().encode())
    tmp = path.with_name(path.name + ".tmp")
    with tmp.open("wb") as fh:
        fh.write(header)
        fh.write(payload)
        fh.flush()
        os.fsync(fh.fileno())
    tmp.replace(path)
    return path


def read_checkpoint(path: Path) -> dict[str, Any]:
    """The state dict of a checkpoint whose header, digest and keys check out."""
    try:
        raw = path.read_bytes()
    except FileNotFoundError as exc:
        raise CheckpointError(f"no checkpoint at {path}") from exc
    except OSError as exc:
        raise CheckpointError(f"{path}: cannot read: {exc.strerror or exc}") from exc
    header, _, payload = raw.partition(b"\n")
    parts = header.split(b" ")
    if len(parts) != 3 or parts[0] != MAGIC:
        raise CheckpointError(
            f"{path}: not an mrguide checkpoint (or one written before format {FORMAT}, which had no digest)"
        )
    if parts[1] != str(FORMAT).encode():
        raise CheckpointError(
            f"{path}: checkpoint format {parts[1].decode(errors='replace')}, this version reads {FORMAT}"
        )
    if hashlib.sha256(payload).hexdigest().encode() != parts[2]:
        raise CheckpointError(f"{path}: corrupt: the SHA-256 digest of its contents does not match its header")
    try:
        state = torch.load(io.BytesIO(payload), weights_only=False)
    except Exception as exc:  # torch raises many kinds on a damaged payload
        raise CheckpointError(f"{path}: not a readable checkpoint ({type(exc).__name__}: {exc})") from exc
    missing = [k for k in REQUIRED if not isinstance(state, dict) or k not in state]
    if missing:
        raise CheckpointError(f"{path}: incomplete checkpoint: no {', '.join(missing)}")
    return state


def with_defaults(stored: Any, defaults: Any) -> Any:
    """`stored` (a checkpoint's configuration) in the shape of `defaults` (today's, at their defaults), at any depth: a
    setting added after the checkpoint was written counts as its default, so older runs still resume; one that
    training no longer reads (a cell's [plant], the sections of learners the run does not train) is left out."""
    if not isinstance(stored, dict) or not isinstance(defaults, dict):
        return stored
    return {k: with_defaults(stored[k], v) if k in stored else v for k, v in defaults.items()}
