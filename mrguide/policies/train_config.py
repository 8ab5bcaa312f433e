"""What a training run is configured with: [train] of a TOML config beside the learner's and the guidance's sections,
and the fingerprint a checkpoint must match to be resumed."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any

from mrguide.config import ConfigError, Range, check_ranges, load_section, replace_path, to_dict
from mrguide.policies.choices import LEARNER_NAMES, OVERRIDE_SECTIONS, Learner
from mrguide.policies.ddpg import DDPGConfig
from mrguide.policies.guidance import GuidanceConfig
from mrguide.policies.sac import SACConfig
from mrguide.robot import RobotSpec
from mrguide.twin.env import EnvConfig


@dataclass(frozen=True)
class TrainConfig:
    """A training run ([train] in a TOML config, with [ddpg] and [guidance] beside it)."""

    total_steps: Annotated[int, Range(1, 10**9)] = 20_000  # paper: 20k timesteps (Fig. 3)
    #: "ddpg" (the paper's learner, [ddpg]) or "sac" (the RLPD-style peer, [sac]; `mrguide experiment peers`).
    learner: Learner | str = "ddpg"  # a shipped learner or a registered one
    seed: Annotated[int, Range(0, 2**32 - 1)] = 0
    batch_size: Annotated[int, Range(1, 1 << 20)] = 256  # Table I
    buffer_size: Annotated[int, Range(1, 10**8)] = 1_000_000  # Table I
    learning_starts: Annotated[int, Range(1, 10**9)] = 256  # updates begin once this many transitions are stored (ours)
    #: steps between deterministic evaluations (convergence is judged on them)
    eval_every: Annotated[int, Range(1, 10**9)] = 1_000
    #: per evaluation; each evaluation draws new start states (see Trainer.evaluate)
    eval_episodes: Annotated[int, Range(1, 10**5)] = 10
    checkpoint_every: Annotated[int, Range(1, 10**9)] = 2_000  # steps; checkpoints are written at the next episode end
    torch_threads: Annotated[int, Range(1, 1024)] = 1

    def __post_init__(self) -> None:
        check_ranges(self, "train")
        if self.learner not in LEARNER_NAMES:
            raise ConfigError(f"train.learner = {self.learner!r}: expected one of {', '.join(LEARNER_NAMES)}")


def load_sac_config(path: str | Path | None) -> SACConfig:
    """[sac] of a training config (the peer learner's settings)."""
    return load_section(SACConfig, path, "sac")


def load_train_config(path: str | Path | None) -> tuple[TrainConfig, DDPGConfig, GuidanceConfig, EnvConfig]:
    return (
        load_section(TrainConfig, path, "train"),
        load_section(DDPGConfig, path, "ddpg"),
        load_section(GuidanceConfig, path, "guidance"),
        EnvConfig.load(path),
    )


def arm_record(spec: RobotSpec) -> dict[str, Any]:
    """The arm a run trains, resolved from its arm file and overrides, in the form checkpoints recorded before
    arm files (the [robot] values then), so a UR5 run checkpointed before them still resumes."""
    values = {
        k: tuple(float(v) for v in getattr(spec, k))
        for k in ("q_lower", "q_upper", "v_max", "a_max", "j_max", "q_home")
    }
    return {
        "name": spec.name,
        "tool_offset": float(spec.T_flange_tcp[2, 3]),
        **values,
        "workspace": to_dict(spec.workspace),
    }


def run_fingerprint(
    tc: TrainConfig, dc: DDPGConfig, gc: GuidanceConfig, ec: EnvConfig, arm: dict[str, Any], sc: SACConfig
) -> dict:
    """The configuration a checkpoint must match to be resumed (the run's length and cadences may change)."""
    return {
        "train": {k: v for k, v in to_dict(tc).items() if k not in ("total_steps", "checkpoint_every", "eval_every")},
        "ddpg": to_dict(dc),
        "guidance": to_dict(gc),
        "env": {**to_dict(ec), "robot": arm},
        "sac": to_dict(sc),
    }


RunConfigs = tuple[TrainConfig, DDPGConfig, GuidanceConfig, EnvConfig, SACConfig]


def apply_overrides(configs: RunConfigs, overrides: Mapping[str, Any], where: str = "override") -> RunConfigs:
    """`configs` with each dotted override ("<section>.<key>[.<key>…]" → value) set and checked exactly as a value
    read from a file (ConfigError naming `where` and the key otherwise)."""
    tc, dc, gc, ec, sc = configs
    for key, value in overrides.items():
        section, _, path = key.partition(".")
        if section not in OVERRIDE_SECTIONS or not path:
            raise ConfigError(
                f"{where}: {key!r}: expected '<section>.<key>' with section one of {', '.join(OVERRIDE_SECTIONS)}"
            )
        if section == "train":
            tc = replace_path(tc, path, value, where)
        elif section == "ddpg":
            dc = replace_path(dc, path, value, where)
        elif section == "guidance":
            gc = replace_path(gc, path, value, where)
        elif section == "sac":
            sc = replace_path(sc, path, value, where)
        else:
            ec = dataclasses.replace(ec, **{section: replace_path(getattr(ec, section), path, value, where)})
    return tc, dc, gc, ec, sc
