"""The learners a run can train, by name: the one place to add one.

A learner is an agent the trainer drives without knowing which it is (`Learner`): it acts, learns from the
tagged replay buffer after every environment step, says which actor is evaluated and exported, and gives and
takes the state a checkpoint saves. `LEARNERS` maps `train.learner` to its class, the TOML section of its
settings and their dataclass (`register_learner`); the run's root config (`train_config.RunConfig`) reads every
registered learner's section, checks `train.learner` against this table and fingerprints the trained learner's
section. To add a learner: write the class and its config in one module and register it there.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, Protocol

import numpy as np

from mrguide.policies.ddpg import DDPG, DDPGConfig
from mrguide.policies.networks import Actor
from mrguide.policies.replay_buffer import TaggedReplay
from mrguide.policies.sac import SAC, SACConfig
from mrguide.registries import register


class Learner(Protocol):
    """What the trainer, the evaluations and the export ask of a learner."""

    #: Updates made so far (the trainer's mean update time divides by it).
    updates: int
    #: The attributes (torch modules) `act` reads: the weights a learner in its own process publishes to the actor.
    acting_modules: ClassVar[tuple[str, ...]]

    @property
    def policy_actor(self) -> Actor:
        """The deterministic actor that is evaluated and exported."""
        ...

    def act(self, obs: np.ndarray, rng: np.random.Generator | None = None) -> np.ndarray:
        """With `rng`, an exploring action; without, the evaluated policy's; in [-1, 1]."""
        ...

    def learn(
        self, replay: TaggedReplay, lam: float, batch_size: int, rng: np.random.Generator
    ) -> tuple[dict[str, float], float]:
        """One environment step's learning; (update statistics, the minibatch's expert share)."""
        ...

    def state_dict(self) -> dict:
        """Networks, optimizers and counters: what a checkpoint saves to resume it."""
        ...

    def load_state_dict(self, state: dict) -> None:
        """Restore what `state_dict` gave (errors: the checkpoint does not fit this learner)."""
        ...


@dataclass(frozen=True)
class LearnerEntry:
    """A learner's class, the TOML section of its settings and the dataclass they load into."""

    cls: type
    section: str
    config: type


LEARNERS: dict[str, LearnerEntry] = {}


def register_learner(name: str, entry: LearnerEntry) -> None:
    """Make `train.learner = NAME` train `entry`'s class, its settings read from `[entry.section]` of a run config (its
    own, or a section it shares); ValueError if the name is taken."""
    register(LEARNERS, name, entry, "learner")


register_learner("ddpg", LearnerEntry(DDPG, "ddpg", DDPGConfig))
register_learner("sac", LearnerEntry(SAC, "sac", SACConfig))


def make_learner(
    name: str, settings: Any, obs_offset: np.ndarray, obs_scale: np.ndarray, act_dim: int, seed: int
) -> Learner:
    """The learner `name`, built with `settings` (its section's config dataclass)."""
    return LEARNERS[name].cls(obs_offset, obs_scale, act_dim, settings, seed=seed)
