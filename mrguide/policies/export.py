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
from mrguide.deploy.policy import FORMAT, FORMAT_VERSION
from mrguide.policies.ddpg import Actor
from mrguide.robot import RobotSpec
from mrguide.task import ACT_LAYOUT, OBS_LAYOUT, TaskConfig


def export_actor(
    actor: Actor, path: str | Path, robot: RobotSpec, task: TaskConfig, decision_period: float, extra: dict[str, Any] | None = None
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
        "head": {"kind": actor.head, "max_offset": actor.max_offset} if actor.head != "absolute" else {"kind": "absolute"},
        "versions": {"mrguide": __version__, "torch": torch.__version__, "numpy": np.__version__},
        **(extra or {}),
    }
    arrays: dict[str, np.ndarray] = {"metadata": np.array(json.dumps(meta))}
    for i, lin in enumerate(linears):
        W = lin.weight.detach().cpu().numpy().astype(np.float64)
        b = lin.bias.detach().cpu().numpy().astype(np.float64)
        if i == 0 and actor.head != "absolute":  # fold the relative-feature map in: W (F x) = (W F) x
            W = W @ actor.features.detach().cpu().numpy().astype(np.float64)
        if i == 0:  # fold the input scaling in: W (x − o) s + b = (W s) x + (b − W (o s))
            o, sc = (t.detach().cpu().numpy().astype(np.float64) for t in (actor.scaler.offset, actor.scaler.scale))
            W, b = W * sc, b - W @ (o * sc)
        arrays[f"W{i}"] = W
        arrays[f"b{i}"] = b
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp.npz")
    np.savez(tmp, **arrays)
    tmp.replace(path)
    return path
