"""One training run of an experiment: what it trains, where it writes, and how it resumes.

A run directory is the unit of work and of resumption: `done` marks a finished run (it is skipped), a
`checkpoint.pt` an interrupted one (it resumes from there), anything else starts afresh. So killing an
experiment and starting it again only finishes what is left.
"""

from __future__ import annotations

import dataclasses
import json
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from mrguide.policies.train_config import RunConfig


@dataclass(frozen=True)
class TrainRun:
    """A training run: base config file, overrides ("guidance.noise.sigma" → 0.05, ...), seed, steps."""

    name: str  # relative run directory, e.g. "guided/seed3" or "sigma_0.05/seed3"
    seed: int
    steps: int
    guided: bool
    config: str | None = None
    overrides: dict[str, Any] = field(default_factory=dict)
    #: "" = the configured expert source in process; "bot" = over the wire: a live session answered by the
    #: annotation bot with the run's guidance.noise (mrguide.annotation.bot_session).
    client: str = ""

    def directory(self, root: Path) -> Path:
        return root / self.name


@dataclass(frozen=True)
class RunResult:
    """What a finished run reports: wall time, mean update time, its directory."""

    name: str
    wall_s: float
    update_ms: float
    steps: int


def run_config(run: TrainRun, where: str = "experiment") -> RunConfig:
    """The root config `run` trains with: its file (parsed once), its seed, steps and guidance, then its overrides."""
    from mrguide.policies.train_config import RunConfig

    cfg = RunConfig.load(run.config)
    guidance = dataclasses.replace(cfg.guidance, enabled=run.guided)
    if run.client == "bot":  # the marks come over the wire: the person's source
        guidance = dataclasses.replace(guidance, source="live")
    cfg = cfg.replace(train=dataclasses.replace(cfg.train, total_steps=run.steps, seed=run.seed), guidance=guidance)
    return cfg.with_overrides(run.overrides, f"{where}: override")


def run_record(run: TrainRun) -> dict[str, Any]:
    """What a run's run.json holds: first the whole configuration it trains with (every section, defaults and
    overrides resolved), how the update is built, then the run as the experiment described it."""
    from mrguide.config import to_dict
    from mrguide.policies.ddpg_update import update_build

    cfg = run_config(run)
    effective = {"train": to_dict(cfg.train), "ddpg": to_dict(cfg.learners["ddpg"]), "guidance": to_dict(cfg.guidance)}
    effective["env"] = to_dict(cfg.env)
    if cfg.learner_section != "ddpg":
        effective[cfg.learner_section] = to_dict(cfg.learner)
    return {"effective_config": effective, "update": update_build(), **dataclasses.asdict(run)}


def check_same_config(run: TrainRun, root: Path) -> None:
    """ConfigError if `run` has started or finished in `root` with another configuration than it would train with
    now (an edited experiment file, another --set): its results would be mixed with the new ones."""
    from mrguide.config import ConfigError

    out = run.directory(root)
    if not ((out / "done").exists() or (out / "checkpoint.pt").exists()):
        return
    try:
        stored = json.loads((out / "run.json").read_text())["effective_config"]
    except (OSError, ValueError, KeyError, TypeError):
        return  # no record to compare (runs made before run.json held the configuration)
    now = json.loads(json.dumps(run_record(run)["effective_config"]))
    diff = _first_difference(stored, now)
    if diff:
        raise ConfigError(
            f"{out} was trained with another configuration ({diff}); give another --out, or remove that run"
        )


def _first_difference(was: Any, now: Any, key: str = "") -> str:
    """The first key whose value differs between two JSON trees, as 'key: was → now' ('' if none). A key only one
    of them has is no difference: a field added to the code since keeps its old behaviour by default."""
    if isinstance(was, dict) and isinstance(now, dict):
        for k in sorted(set(was) & set(now)):
            diff = _first_difference(was[k], now[k], f"{key}.{k}" if key else k)
            if diff:
                return diff
        return ""
    return "" if was == now else f"{key}: {was!r} → {now!r}"


def is_done(run: TrainRun, root: Path) -> bool:
    return (run.directory(root) / "done").exists()


def progress_steps(run: TrainRun, root: Path) -> int:
    """Steps a run has reached, read from the last line of its metrics.csv (0 if none)."""
    path = run.directory(root) / "metrics.csv"
    try:
        with path.open("rb") as fh:
            fh.seek(max(0, path.stat().st_size - 512))
            last = fh.read().splitlines()[-1].decode()
        return int(last.split(",", 1)[0])
    except (OSError, IndexError, ValueError):
        return 0


def train(run: TrainRun, root: str, on_episode: Callable[[dict], None] | None = None) -> RunResult:
    """Train `run` to the end (resuming from its checkpoint if it has one) and mark it done."""
    from mrguide.policies.export import export_actor
    from mrguide.policies.train import Trainer

    out = run.directory(Path(root))
    if (out / "done").exists():
        return finished(run, Path(root))
    cfg = run_config(run)
    out.mkdir(parents=True, exist_ok=True)
    if not (out / "checkpoint.pt").exists():
        for stale in ("metrics.csv", "eval.csv", "annotations.jsonl"):  # a start that never checkpointed
            (out / stale).unlink(missing_ok=True)
    (out / "run.json").write_text(json.dumps(run_record(run), indent=1) + "\n")
    bot, factory = None, None
    if run.client == "bot":
        from mrguide.annotation.bot_session import BotSession

        stop = threading.Event()
        bot = BotSession(cfg.guidance.noise, run.seed, on_failure=stop.set)
        factory = bot.source_factory
    try:
        tr = Trainer(cfg, out, factory)
    except BaseException:
        if bot:
            bot.close()
        raise
    if bot:
        tr.stop_requested = stop
        on_episode = _publishing(bot, tr, on_episode)
    try:
        if (out / "checkpoint.pt").exists():
            tr.load_checkpoint()
        tr.run(on_episode)
        if bot and bot.error:
            raise RuntimeError(f"{run.name}: the annotation bot stopped: {bot.error}")
        tr.save_checkpoint()
        export_actor(
            tr.agent.policy_actor,
            out / "policy.npz",
            tr.env.robot_spec,
            tr.env.task_cfg,
            tr.env.twin_cfg.decision_period,
            {"trained": {"steps": tr.counters.step, "seed": run.seed, "guidance": run.guided, "run": run.name}},
        )
        tmp = out / "done.tmp"
        tmp.write_text(
            json.dumps(
                {"wall_s": round(tr.wall_s(), 1), "update_ms": round(tr.update_ms(), 3), "steps": tr.counters.step}
            )
            + "\n"
        )
        tmp.replace(out / "done")
    finally:
        tr.close()
        if bot:
            bot.close()
    return finished(run, Path(root))


def _publishing(bot: Any, tr: Any, on_episode: Callable[[dict], None] | None) -> Callable[[dict], None]:
    """`on_episode` that first publishes the run's status to the bot's session, as `mrguide train --expert live` does
    to the page: the bot's person sees the grip the cell uses, and steps in where they see it wrong."""
    from mrguide.policies.session_status import SessionStatus

    status = SessionStatus(tr)

    def publish(row: dict) -> None:
        status.episode(row)
        bot.session.publish(**status.fields())
        if on_episode is not None:
            on_episode(row)

    return publish


def finished(run: TrainRun, root: Path) -> RunResult:
    """The result a finished run recorded in its `done` marker."""
    text = (run.directory(root) / "done").read_text()
    try:
        d = json.loads(text)
    except json.JSONDecodeError:  # runs finished before this module: "wall_s\nupdate_ms\n"
        wall, update = (float(x) for x in text.split()[:2])
        d = {"wall_s": wall, "update_ms": update, "steps": run.steps}
    return RunResult(run.name, float(d["wall_s"]), float(d["update_ms"]), int(d["steps"]))
