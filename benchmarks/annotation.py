"""Live annotation round trips over loopback: trainer → broker → client → answer → trainer.

    python benchmarks/annotation.py [--requests 500] [--browser-requests 100]

1. Bot: `broker.request` (as the trainer calls it) to the `LiveAnswer` it returns, answered by
   `mrguide annotate bot` (its own process) over a real WebSocket, while a third process floods the server
   with the protocol's bad messages (malformed JSON, NaN, stale ids, out-of-box targets, oversize frames).
2. Browser: the same, answered by the real page in headless Chromium (Debian's chromium through
   playwright, WebGL on SwiftShader), submitted by the page's test hook (`autoSubmit`) as soon as the
   page has shown the request (after 5 untimed warm-up requests); the answer must be the page's start
   target, the TCP.
3. A person with the mouse alone: pick and place requests answered on the page by a click on the part or
   the goal and a click on Submit (`AnnotationPage.mark_like_a_person`); the answer must be the part's top
   centre or the goal. Counts the clicks and the page's interaction time per mark (machine time: what the page
   itself costs, not a person's thinking).

An answer is lost when a request ends without the answer that was sent for it. Prints a table and, last,
one JSON line: round_trip_p99_ms (target <= 20), browser_round_trip_p99_ms (<= 150), answers_lost (0),
bad_messages_survived, actions_per_mark (<= 2), page_interaction_ms_per_mark.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import multiprocessing
import platform
import subprocess
import sys
import threading
import time

import aiohttp
import numpy as np

from mrguide.annotation.broker import AnnotationBroker, LiveAnswer
from mrguide.annotation.headless import HeadlessBrowser
from mrguide.annotation.live import hello_fields
from mrguide.annotation.protocol import AnnotationRequest
from mrguide.annotation.server import AnnotationServer
from mrguide.policies.experts import OracleExpert
from mrguide.robot import load_robot
from mrguide.task import PICK_PHASE, PLACE_PHASE, TaskConfig, observation, progress

WARMUP = 5  # browser requests answered before timing starts
BAD_MESSAGES = (
    "{not json",
    "[1, 2]",
    '{"type": "teleport"}',
    '{"type": "answer", "id": "stale-1", "target": [0.5, 0, 0.1], "vacuum": true}',
    '{"type": "answer", "id": "x", "target": [NaN, 0, 0.1], "vacuum": true}',
    '{"type": "claim"}',
    "x" * 70_000,
    '{"type": "answer", "id": "x", "target": [0.5, 0, -3], "vacuum": true}',
    '{"type": "hello", "protocol": 1, "client": 9}',
    '{"type": "ping", "x": ' + "[" * 3000 + "]" * 3000 + "}",
    '{"type": "answer", "id": "x", "target": [1' + "0" * 500 + ", 0, 0.1]}",
)  # (a hello of another protocol is refused and disconnected: the flooder would stop flooding)


def requests(n: int, seed: int = 0) -> list[AnnotationRequest]:
    """Requests over the task's phases with objects and goals spread over their regions."""
    spec, rng = load_robot(), np.random.default_rng(seed)
    out = []
    for k in range(n):
        obj = np.array([rng.uniform(0.4, 0.6), rng.uniform(-0.15, 0.0), 0.025])
        goal = np.array([rng.uniform(0.4, 0.6), rng.uniform(0.12, 0.3), 0.025])
        tcp = np.array([0.5, 0.05, 0.25])
        phase = k % 5
        obs = observation(tcp, -1, progress(phase), obj, goal)
        out.append(AnnotationRequest(phase, spec.q_home, tcp, False, obj, np.array([0, 0, 0, 1.0]), goal, obs))
    return out


def flood(url: str, stop) -> None:
    """A misbehaving client: a bad message every 2 ms."""

    async def run() -> None:
        async with aiohttp.ClientSession() as http, http.ws_connect(url) as ws:
            k = 0
            while not stop.is_set():
                await ws.send_str(BAD_MESSAGES[k % len(BAD_MESSAGES)])
                k += 1
                await asyncio.sleep(0.002)

    asyncio.run(run())


def bot_round_trips(broker: AnnotationBroker, server: AnnotationServer, n: int) -> tuple[list[float], int, int]:
    """(round trips in s, answers lost, bad messages refused meanwhile); bot and flooder are processes of their own."""
    bot = subprocess.Popen(
        [sys.executable, "-m", "mrguide.cli", "annotate", "bot", "--url", server.url, "--count", str(n)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    ctx = multiprocessing.get_context("spawn")
    stop = ctx.Event()
    flooder = ctx.Process(target=flood, args=(server.ws_url, stop), daemon=True)
    flooder.start()
    oracle = OracleExpert(TaskConfig())
    while broker.stats.refused.total() == 0 or broker.client_count < 2:  # both clients connected
        time.sleep(0.01)
    times, lost = [], 0
    for req in requests(n):
        t = time.perf_counter()
        res = broker.request(req, timeout=5.0)
        times.append(time.perf_counter() - t)
        lost += int(not (isinstance(res, LiveAnswer) and np.array_equal(res.target, oracle.annotate(req.obs).target)))
    stop.set()
    flooder.join(10)
    bot.wait(10)
    return times, lost, broker.stats.refused.total()


def browser_round_trips(broker: AnnotationBroker, server: AnnotationServer, n: int) -> tuple[list[float], int]:
    """(round trips in s, answers lost) with the page answering through its test hook."""
    reqs = requests(n, seed=1)
    with HeadlessBrowser() as browser:
        page = browser.open(server.url)
        page.wait_robot()
        page.auto_submit(True)  # the page answers each request the moment it has shown it: its start target (the TCP)
        for req in requests(WARMUP, seed=2):  # the first answers also compile shaders and lay out the panel
            broker.request(req, timeout=30.0)
        times, lost = [], 0
        for req in reqs:
            t = time.perf_counter()
            res = broker.request(req, timeout=10.0)
            times.append(time.perf_counter() - t)
            lost += int(not (isinstance(res, LiveAnswer) and np.allclose(res.target, np.round(req.tcp, 4), atol=1e-9)))
    return times, lost


def person_marks(broker: AnnotationBroker, server: AnnotationServer, n: int) -> tuple[list[int], list[float], int]:
    """(clicks per mark, page interaction s per mark, answers lost) for pick and place requests answered with the
    mouse alone."""
    reqs = [r for r in requests(5 * n, seed=3) if r.phase in (PICK_PHASE, PLACE_PHASE)][:n]
    actions, seconds, lost = [], [], 0
    with HeadlessBrowser() as browser:
        page = browser.open(server.url)
        page.wait_robot()
        done: list[dict] = []
        for req in reqs:
            ask = threading.Thread(target=lambda r=req: done.append({"req": r, "res": broker.request(r, timeout=30.0)}))
            ask.start()
            mark = page.mark_like_a_person(done[-1]["res"].request_id if done else None)
            ask.join(30)
            actions.append(mark["actions"])
            seconds.append(mark["seconds"])
            res = done[-1]["res"]
            top = req.object_position if req.phase == PICK_PHASE else req.goal
            expected = np.array([top[0], top[1], TaskConfig().object_height])
            lost += int(not (isinstance(res, LiveAnswer) and np.allclose(res.target, expected, atol=2e-4)))
        page.close()
    return actions, seconds, lost


def pct(x: list[float], q: float) -> float:
    return float(np.percentile(np.asarray(x) * 1e3, q))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--requests", type=int, default=500)
    ap.add_argument("--browser-requests", type=int, default=100)
    ap.add_argument("--person-marks", type=int, default=20)
    args = ap.parse_args()
    spec = load_robot()
    broker = AnnotationBroker(spec.workspace, hello_fields(spec, TaskConfig()))
    server = AnnotationServer(broker, spec, port=0)
    server.start()
    try:
        bot_t, bot_lost, bad = bot_round_trips(broker, server, args.requests)
        browser_t, browser_lost = browser_round_trips(broker, server, args.browser_requests)
        person_actions, person_s, person_lost = person_marks(broker, server, args.person_marks)
    finally:
        broker.close()
        server.stop()
    print(f"machine: {platform.machine()}, {platform.python_version()}; loopback, server and trainer in one process")
    print(f"{'path':<10} {'requests':>8} {'p50 ms':>8} {'p99 ms':>8} {'max ms':>8} {'lost':>5}")
    for name, t, lost in (("bot", bot_t, bot_lost), ("browser", browser_t, browser_lost)):
        print(f"{name:<10} {len(t):>8} {pct(t, 50):>8.2f} {pct(t, 99):>8.2f} {pct(t, 100):>8.2f} {lost:>5}")
    print(f"bad messages refused by the broker during the bot run, none of which stopped an answer: {bad}")
    print(
        f"a person with the mouse: {len(person_actions)} marks, median {np.median(person_actions):.0f} clicks and "
        f"{1e3 * np.median(person_s):.0f} ms of page interaction per mark, {person_lost} lost"
    )
    print(
        json.dumps(
            {
                "round_trip_p50_ms": round(pct(bot_t, 50), 3),
                "round_trip_p99_ms": round(pct(bot_t, 99), 3),
                "browser_round_trip_p50_ms": round(pct(browser_t, 50), 3),
                "browser_round_trip_p99_ms": round(pct(browser_t, 99), 3),
                "answers_lost": bot_lost + browser_lost + person_lost,
                "bad_messages_survived": bad,
                "requests": len(bot_t),
                "browser_requests": len(browser_t),
                "actions_per_mark": float(np.median(person_actions)),
                "page_interaction_ms_per_mark": round(1e3 * float(np.median(person_s)), 1),
                "person_marks": len(person_actions),
            }
        )
    )


if __name__ == "__main__":
    main()
