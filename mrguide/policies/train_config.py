"""What a training run is configured with: [train] of a TOML config beside the learner's and the guidance's sections,
gathered in one root (`RunConfig`, parsed once), and the fingerprint a checkpoint must match to be resumed."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any

from mrguide.config import RUN_SECTIONS, ConfigError, ConfigFile, Range, check_ranges, replace_path, to_dict
from mrguide.policies.guidance import GuidanceConfig
from mrguide.policies.learners import LEARNERS
from mrguide.robot import RobotSpec
from mrguide.twin.env import EnvConfig


@dataclass(frozen=True)
class TrainConfig:
    """A training run ([train] in a TOML config, with [ddpg] and [guidance] beside it)."""

    total_steps: Annotated[int, Range(1, 10**9)] = 20_000  # paper: 20k timesteps (Fig. 3)
    #: "ddpg" (the paper's learner, [ddpg]), "sac" (the RLPD-style peer, [sac]; `mrguide experiment peers`), or any
    #: learner a module registered (`policies.learners`); checked by the run's root config, which has the registry.
    learner: str = "ddpg"
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
    #: Run the learner's updates in a process of their own (`policies/learner_process.py`): the env loop acts with the
    #: latest weights it has received and never waits for an update. false: updates alternate with steps in one thread.
    learner_process: bool = False
    #: With learner_process: the learner publishes the actor's weights every this many `learn` calls.
    publish_every: Annotated[int, Range(1, 10**6)] = 10

    def __post_init__(self) -> None:
        check_ranges(self, "train")


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


#: [train] settings that a resumed run may change: its length and cadences.
RESUMABLE_CHANGES = ("total_steps", "checkpoint_every", "eval_every")


def _learner_defaults() -> dict[str, Any]:
    return {entry.section: entry.config() for entry in LEARNERS.values()}


@dataclass(frozen=True)
class RunConfig:
    """The whole configuration of a training run: one frozen root, parsed once from one file (`load`), with its
    sections by name. `learners` holds the section of every registered learner (section name → its config); the run
    trains the one `train.learner` names (`learner`)."""

    train: TrainConfig = field(default_factory=TrainConfig)
    guidance: GuidanceConfig = field(default_factory=GuidanceConfig)
    env: EnvConfig = field(default_factory=EnvConfig)
    learners: dict[str, Any] = field(default_factory=_learner_defaults)

    def __post_init__(self) -> None:
        if self.train.learner not in LEARNERS:
            raise ConfigError(f"train.learner = {self.train.learner!r}: expected one of {', '.join(LEARNERS)}")

    @classmethod
    def load(cls, path: str | Path | None) -> RunConfig:
        """Every section a training run reads, from `path` parsed once (defaults where absent)."""
        sections = {entry.section: entry.config for entry in LEARNERS.values()}
        file = ConfigFile.read(path, tuple(dict.fromkeys((*RUN_SECTIONS, *sections))))
        train, guidance = file.section(TrainConfig, "train"), file.section(GuidanceConfig, "guidance")
        env = EnvConfig.from_file(file)
        learners: dict[str, Any] = {name: file.section(config, name) for name, config in sections.items()}
        try:
            return cls(train, guidance, env, learners)
        except ConfigError as exc:  # the root's own check (the learner's name): say where
            raise ConfigError(f"{path} [train]: {exc}") from exc

    @property
    def learner_section(self) -> str:
        return LEARNERS[self.train.learner].section

    @property
    def learner(self) -> Any:
        """The settings of the learner this run trains."""
        return self.learners[self.learner_section]

    def sections(self) -> dict[str, Any]:
        """Every section by name, as a file holds them (what `mrguide config show` prints)."""
        env = {"robot": self.env.robot, "twin": self.env.twin, "task": self.env.task}
        return {"train": self.train, **self.learners, "guidance": self.guidance, **env}

    def replace(self, **sections: Any) -> RunConfig:
        """This config with whole sections replaced by name (`train=...`, `ddpg=...`, `twin=...`)."""
        env = {k: sections.pop(k) for k in ("robot", "twin", "task") if k in sections}
        learners = {k: sections.pop(k) for k in list(sections) if k in self.learners}
        return dataclasses.replace(
            self,
            env=dataclasses.replace(self.env, **env),
            learners={**self.learners, **learners},
            **sections,
        )

    def with_overrides(self, overrides: Mapping[str, Any], where: str = "override") -> RunConfig:
        """This config with each dotted override ("<section>.<key>[.<key>…]" → value) set, checked exactly as a value
        read from a file (ConfigError naming `where` and the key otherwise)."""
        cfg, names = self, self.sections()
        for key, value in overrides.items():
            section, _, path = key.partition(".")
            if section not in names or not path:
                raise ConfigError(
                    f"{where}: {key!r}: expected '<section>.<key>' with section one of {', '.join(names)}"
                )
            cfg = cfg.replace(**{section: replace_path(cfg.sections()[section], path, value, where)})
        return cfg

    def fingerprint(self, arm: dict[str, Any]) -> dict:
        """What a checkpoint must match to be resumed: exactly what training reads (the trained learner's section,
        not the others; the env's sections and the arm they resolve to; no cell's [plant])."""
        train = {k: v for k, v in to_dict(self.train).items() if k not in RESUMABLE_CHANGES}
        return {
            "train": train,
            self.learner_section: to_dict(self.learner),
            "guidance": to_dict(self.guidance),
            "env": {**to_dict(self.env), "robot": arm},
        }
