"""Fixtures for the live-annotation tests: a broker, a served broker, requests, an async WebSocket client."""

from __future__ import annotations

import asyncio
import json
import threading
import time
from concurrent.futures import Future

import aiohttp
import numpy as np
import pytest

from mrguide.annotation.broker import AnnotationBroker
from mrguide.annotation.headless import HeadlessBrowser, chromium_path
from mrguide.annotation.live import hello_fields
from mrguide.annotation.protocol import AnnotationRequest
from mrguide.annotation.server import WEB_DIR, AnnotationServer
from mrguide.motion.kinematics import Kinematics
from mrguide.robot import load_robot
from mrguide.task import TaskConfig, observation, progress

OBJ = np.array([0.5, -0.08, 0.025])
GOAL = np.array([0.48, 0.2, 0.025])


def make_request(
    phase: int = 1,
    remark: bool = False,
    obj: np.ndarray = OBJ,
    goal: np.ndarray = GOAL,
    quat: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0),
) -> AnnotationRequest:
    """The arm at home (TCP by Pinocchio FK), an object and a goal on the table, in phase `phase`."""
    spec = load_robot()
    tcp = Kinematics(spec).tcp_position(spec.q_home)
    obs = observation(tcp, -1, progress(phase), obj, goal)
    return AnnotationRequest(
        phase,
        spec.q_home.copy(),
        tcp,
        False,
        obj,
        np.array(quat),
        goal,
        obs,
        remark,
        np.array([0.5, -0.08, 0.06]) if remark else None,
    )


def ask_in_thread(
    broker: AnnotationBroker, req: AnnotationRequest, timeout: float | None = None, acknowledge: bool = True
) -> Future:
    """broker.request in a thread (it blocks, as in the trainer); the result arrives in the future."""
    fut: Future = Future()

    def run() -> None:
        try:
            fut.set_result(broker.request(req, timeout, acknowledge))
        except BaseException as exc:  # handed to the test
            fut.set_exception(exc)

    threading.Thread(target=run, daemon=True).start()
    return fut


@pytest.fixture
def broker() -> AnnotationBroker:
    spec = load_robot()
    return AnnotationBroker(
        spec.workspace, {"robot": {"workspace": {"lo": spec.workspace.lo.tolist(), "hi": spec.workspace.hi.tolist()}}}
    )


@pytest.fixture
def served(broker, tmp_path):
    """(broker, server) on a free port, serving a stub page."""
    (tmp_path / "index.html").write_text("<!doctype html><title>stub</title>")
    server = AnnotationServer(broker, load_robot(), port=0, web_dir=tmp_path)
    server.start()
    yield broker, server
    broker.close()
    server.stop()


@pytest.fixture(scope="module")
def browser():
    """Headless Chromium for the real page. Missing pieces are errors, not skips: .ci/run installs chromium,
    ./run.sh runs `npm ci`."""
    chromium_path()
    assert (WEB_DIR / "node_modules" / "three").is_dir(), "run `npm ci` in mrguide/annotation/web (./run.sh does)"
    with HeadlessBrowser(viewport=(960, 600)) as b:  # a smaller canvas is faster on SwiftShader
        yield b


@pytest.fixture
def spec():
    return load_robot()


@pytest.fixture
def page_served(spec):
    """(broker, server) on a free port, serving the real page."""
    broker = AnnotationBroker(spec.workspace, hello_fields(spec, TaskConfig()))
    server = AnnotationServer(broker, spec, port=0)
    server.start()
    yield broker, server
    broker.close()
    server.stop()


class Client:
    """A test client over a real WebSocket: `recv(type)` skips messages of other types."""

    def __init__(self, ws: aiohttp.ClientWebSocketResponse):
        self.ws = ws
        self.hello: dict = {}

    async def send(self, msg) -> None:
        await self.ws.send_str(msg if isinstance(msg, str) else json.dumps(msg))

    async def recv(self, kind: str | None = None, timeout: float = 5.0) -> dict:
        async def next_of_kind() -> dict:
            while True:
                msg = await self.ws.receive()
                if msg.type is not aiohttp.WSMsgType.TEXT:
                    raise ConnectionError(f"connection ended: {msg.type}")
                data = json.loads(msg.data)
                if kind is None or data["type"] == kind:
                    return data

        return await asyncio.wait_for(next_of_kind(), timeout)


async def connect(session: aiohttp.ClientSession, server: AnnotationServer, kind: str = "bot") -> Client:
    """Connect, say hello, and wait for the server's hello and the ack of ours (kept in `client.hello`)."""
    ws = await session.ws_connect(server.ws_url)
    client = Client(ws)
    client.hello = await client.recv("hello")
    await client.send({"type": "hello", "protocol": 1, "client": kind})
    ack = await client.recv("ack")
    assert ack["for"] == "hello" and ack["accepted"], ack
    return client


def wait_until(predicate, timeout: float = 5.0) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if predicate():
            return True
        time.sleep(0.01)
    return predicate()
