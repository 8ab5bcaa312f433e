"""Export a trained actor to the numpy policy file that `mrguide.deploy.policy` loads."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torch import nn

from mrguide import __version__
from mrguide.config import to_dict
from mrguide.deploy.policy import FORMAT, FORMAT_VERSION, HEAD_KIND
from mrguide.policies.networks import CARRY_PROGRESS, MAX_OFFSET, Actor
from mrguide.robot import RobotSpec
from mrguide.task import ACT_LAYOUT, OBS_LAYOUT, TaskConfig


def export_actor(
    actor: Actor,
    path: str | Path,
    robot: RobotSpec,
    task: TaskConfig,
    decision_period: float,
    extra: dict[str, Any] | None = None,
) -> Path:
    """Write the actor's linear layers and metadata to `path` (npz), atomically. The metadata names the arm
    (`robot`: name, fingerprint, joints), which `ExportedPolicy.load` requires of the configured arm."""
    workspace = robot.workspace
    linears = [m for m in actor.net if isinstance(m, nn.Linear)]
    acts = ["relu"] * (len(linears) - 1) + ["tanh"]
    meta = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "obs_layout": list(OBS_LAYOUT),
        "act_layout": list(ACT_LAYOUT),
        "activations": acts,
        "workspace": {"low": list(workspace.low), "high": list(workspace.high)},
        "robot": {"name": robot.name, "fingerprint": robot.fingerprint, "joints": list(robot.joint_names)},
        "task": to_dict(task),
        "decision_period": decision_period,
        "head": {"kind": HEAD_KIND, "max_offset": MAX_OFFSET, "carry_progress": CARRY_PROGRESS},
        "versions": {"mrguide": __version__, "torch": torch.__version__, "numpy": np.__version__},
        **(extra or {}),
    }
    arrays: dict[str, np.ndarray] = {"metadata": np.array(json.dumps(meta))}
    arrays["W0"], arrays["b0"] = _first_layer(actor, "features")
    for i, lin in enumerate(linears[1:], start=1):
        arrays[f"W{i}"] = lin.weight.detach().cpu().numpy().astype(np.float64)
        arrays[f"b{i}"] = lin.bias.detach().cpu().numpy().astype(np.float64)
    arrays["W0_carry"], arrays["b0_carry"] = _first_layer(actor, "carry_features")
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp.npz")
    np.savez_compressed(tmp, **arrays)  # type: ignore[arg-type]  # numpy's stub: **kwds vs allow_pickle: bool
    tmp.replace(path)
    return path


def _first_layer(actor: Actor, feature_map: str) -> tuple[np.ndarray, np.ndarray]:
    """Layer 0 acting on the raw observation: the feature map `feature_map` and the input scaling folded into the
    weights, W F ((x − o) s) + b = (W F s) x + (b − W F (o s))."""
    lin = next(m for m in actor.net if isinstance(m, nn.Linear))
    W = lin.weight.detach().cpu().numpy().astype(np.float64)
    b = lin.bias.detach().cpu().numpy().astype(np.float64)
    W = W @ getattr(actor, feature_map).detach().cpu().numpy().astype(np.float64)
    o, sc = (t.detach().cpu().numpy().astype(np.float64) for t in (actor.scaler.offset, actor.scaler.scale))
    return W * sc, b - W @ (o * sc)
