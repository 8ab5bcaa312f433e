"""`mrguide annotate bot`: a scripted client that answers over the wire like the simulated annotator.

It reconstructs the policy observation from each request, marks the task model's waypoint with the
simulated annotator's noise (same RNG stream as the in-process annotator of the same training seed), and
answers through the protocol like a person at the page would. For demos, tests and benchmarks.
"""

from __future__ import annotations

import asyncio
import logging
import time
from dataclasses import dataclass, field
from typing import Any
from urllib.parse import parse_qs, urlsplit, urlunsplit

import aiohttp
import numpy as np

from mrguide.annotation.protocol import PROTOCOL_VERSION
from mrguide.policies.experts import ANNOTATOR_SEED_OFFSET, AnnotatorNoise, SimulatedAnnotator
from mrguide.robot import Workspace
from mrguide.task import PICK_PHASE, TaskConfig, observation, progress

log = logging.getLogger(__name__)


class BotError(RuntimeError):
    """The bot cannot reach or understand the server."""


@dataclass(frozen=True)
class BotOptions:
    url: str  # the page URL printed by `mrguide train --expert live` (token included)
    noise: AnnotatorNoise = AnnotatorNoise()
    seed: int = 0  # the training seed whose simulated annotator to mimic
    delay_s: float = 0.0  # think time before each answer
    max_answers: int | None = None  # stop after this many answers
    insecure: bool = False  # accept a self-signed certificate (wss:// on a LAN)
    intervene: bool = False  # step in once on connecting (the trainer or the learning cell asks for marks next)
    connect_timeout_s: float = 10.0


@dataclass
class BotReport:
    answers: int = 0
    refused: int = 0
    latencies_s: list[float] = field(default_factory=list)
    intervened: bool = False  # the server accepted the bot's `intervene`
    corrections: int = 0  # times the bot stepped in to correct the grip the status showed (its person knows the part)


def ws_url(page_url: str) -> str:
    """ws(s)://host:port/ws?token=... from the page URL; refuses a URL without a token."""
    parts = urlsplit(page_url)
    if parts.scheme not in ("http", "https", "ws", "wss") or not parts.netloc:
        raise BotError(f"not a page URL: {page_url!r} (expected http(s)://HOST:PORT/?token=...)")
    token = parse_qs(parts.query).get("token")
    if not token:
        raise BotError(f"the URL has no access token: {page_url!r}; copy the whole URL that mrguide train printed")
    scheme = {"http": "ws", "https": "wss"}.get(parts.scheme, parts.scheme)
    return urlunsplit((scheme, parts.netloc, "/ws", f"token={token[0]}", ""))


def obs_from_request(req: dict[str, Any]) -> np.ndarray:
    """The policy observation the trainer asked with (exactly: its float32 values travel as JSON floats)."""
    s = req["state"]
    return observation(
        np.array(s["tcp"]),
        1 if s["vacuum_on"] else -1,
        progress(int(req["phase_index"])),
        np.array(s["object"]["position"]),
        np.array(s["goal"]),
    )


class AnnotationBot:
    """Connects, answers every request it sees, and stops when the server closes the connection."""

    def __init__(self, options: BotOptions):
        self.options = options
        self.url = ws_url(options.url)
        self.report = BotReport(latencies_s=[])
        self._annotator: SimulatedAnnotator | None = None
        self._contested: tuple[list[float] | None, bool] = (None, False)  # the grip stepped in on; accepted yet
        self._shown: list[float] | None = None  # the grip the last status showed

    def run(self) -> BotReport:
        """Answer until the server goes away (training ended) or `max_answers` is reached."""
        asyncio.run(self._main())
        return self.report

    async def _main(self) -> None:
        ctx = not self.options.insecure
        timeout = aiohttp.ClientTimeout(total=None, connect=self.options.connect_timeout_s)
        async with aiohttp.ClientSession(timeout=timeout) as http:
            try:
                async with http.ws_connect(self.url, ssl=ctx, heartbeat=20.0) as ws:
                    await ws.send_json(
                        {"type": "hello", "protocol": PROTOCOL_VERSION, "client": "bot", "name": "mrguide annotate bot"}
                    )
                    await self._serve(ws)
            except aiohttp.WSServerHandshakeError as exc:
                raise BotError(f"{self.url}: the server refused the connection ({exc.status}: {exc.message})") from exc
            except (TimeoutError, aiohttp.ClientConnectionError) as exc:
                raise BotError(f"cannot connect to {self.url}: {exc}") from exc

    async def _serve(self, ws: aiohttp.ClientWebSocketResponse) -> None:
        async for msg in ws:
            if msg.type is not aiohttp.WSMsgType.TEXT:
                continue
            data = msg.json()
            kind = data.get("type")
            if kind == "hello":
                self._configure(data)
                if self.options.intervene and not data.get("request"):
                    await ws.send_json({"type": "intervene"})
                if data.get("request"):
                    await self._answer(ws, data["request"])
            elif kind == "request":
                await self._answer(ws, data)
            elif kind == "status":
                await self._watch(ws, data.get("grasp"))
            elif kind == "ack" and data.get("for") == "intervene":
                self._stepped_in(bool(data.get("accepted")))
            elif kind == "ack" and not data.get("accepted"):
                self.report.refused += 1
                log.warning("server refused our %s: %s", data.get("for"), data.get("reason"))
            if self._done():
                await ws.close()
                return

    async def _watch(self, ws: aiohttp.ClientWebSocketResponse, grasp: list[float] | None) -> None:
        """A person who knows the part and sees the cell grip it wrongly steps in (once per grip shown): the next
        demonstration asks every mark, and their pick answer with `here` corrects the grip."""
        self._shown = grasp
        if self._annotator is None or grasp == self._contested[0] or not self._annotator.corrects(grasp):
            return
        self._contested = (grasp, False)
        await ws.send_json({"type": "intervene"})

    def _stepped_in(self, accepted: bool) -> None:
        """The server's answer to an `intervene`: refused (a request was outstanding), the grip is contested anew at
        the next status."""
        if not accepted:
            self.report.refused += 1
            self._contested = (None, False)
        elif self._contested[0] is not None and not self._contested[1]:
            self._contested = (self._contested[0], True)
            self.report.corrections += 1
        else:
            self.report.intervened = True

    def _configure(self, hello: dict[str, Any]) -> None:
        if self._annotator is not None:
            return
        ws = hello["robot"]["workspace"]
        task = TaskConfig(**hello["task"])
        self._annotator = SimulatedAnnotator(
            task,
            self.options.noise,
            Workspace(tuple(ws["lo"]), tuple(ws["hi"])),
            seed=self.options.seed + ANNOTATOR_SEED_OFFSET,
        )

    async def _answer(self, ws: aiohttp.ClientWebSocketResponse, req: dict[str, Any]) -> None:
        if req.get("claimed_by") or self._annotator is None:
            return
        t0 = time.perf_counter()
        obs = obs_from_request(req)
        ann = self._annotator.correct(obs) if self._correcting(req) else self._annotator.annotate(obs)
        if self.options.delay_s:
            await asyncio.sleep(self.options.delay_s)
        answer = {
            "type": "answer",
            "id": req["id"],
            "target": [float(v) for v in ann.target],
            "vacuum": bool(ann.grip > 0),
        }
        await ws.send_json(answer | ({"here": True} if ann.here else {}))  # a part it knows: it teaches the grasp
        self.report.answers += 1
        self.report.latencies_s.append(time.perf_counter() - t0)

    def _correcting(self, req: dict[str, Any]) -> bool:
        """Whether `req` asks the pick while the page shows a taught grip on the part: the person moves that grip to
        where they judge it belongs (`SimulatedAnnotator.correct`) rather than marking the point afresh."""
        return self._shown is not None and int(req["phase_index"]) == PICK_PHASE

    def _done(self) -> bool:
        m = self.options.max_answers
        return m is not None and self.report.answers >= m
