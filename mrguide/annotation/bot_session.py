"""Guided training over the wire without a person: a live session on a free local port, answered by the
annotation bot (`mrguide annotate bot`) from a thread of the same process — the way an experiment runs a
person's error model through the real protocol, server and broker (`TrainRun.client = "bot"`)."""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable

from mrguide.annotation.bot import AnnotationBot, BotError, BotOptions, BotReport
from mrguide.annotation.live import LiveExpert, LiveOptions, LiveSession
from mrguide.policies.experts import AnnotatorNoise
from mrguide.twin.env import PickPlaceEnv

log = logging.getLogger(__name__)


class BotSession:
    """A `LiveSession` on 127.0.0.1 (any free port) and the bot that answers it; `close()` ends both."""

    def __init__(self, noise: AnnotatorNoise, seed: int, on_failure: Callable[[], None] | None = None):
        self.session = LiveSession(LiveOptions(port=0))
        self.noise, self.seed = noise, seed
        self.on_failure = on_failure  # called (from the bot's thread) when the bot cannot go on
        self.report: BotReport | None = None
        self.error: BaseException | None = None
        self._thread: threading.Thread | None = None

    def source_factory(self, env: PickPlaceEnv) -> LiveExpert:
        """The trainer's expert source: serve for `env`, then start the bot on the served URL."""
        expert = self.session.source_factory(env)
        bot = AnnotationBot(BotOptions(self.session.url, self.noise, self.seed))
        self._thread = threading.Thread(target=self._answer, args=(bot,), name="annotation-bot", daemon=True)
        self._thread.start()
        return expert

    def _answer(self, bot: AnnotationBot) -> None:
        try:
            self.report = bot.run()
        except (BotError, OSError, RuntimeError) as exc:
            self.error = exc
            log.error("annotation bot stopped: %s", exc)
            if self.on_failure:
                self.on_failure()
            self.session.interrupt()

    def close(self) -> None:
        self.session.close()
        if self._thread is not None:
            self._thread.join(timeout=30.0)
