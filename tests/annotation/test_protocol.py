"""Protocol v1 over a real WebSocket: answers, every refusal, claims, reconnects, timeouts, tokens."""

from __future__ import annotations

import asyncio
import json
import re
import threading

import aiohttp
import numpy as np
import pytest

from mrguide.annotation.broker import LiveAnswer, NoAnswer
from mrguide.annotation.protocol import REFUSALS
from tests.annotation.conftest import ask_in_thread, connect, make_request, wait_until


def run(coro):
    return asyncio.run(coro)


def test_hello_request_answer_ack_cancel(served):
    broker, server = served

    async def scenario():
        async with aiohttp.ClientSession() as http:
            c = await connect(http, server)
            hello = c.hello
            assert hello["protocol"] == 1 and hello["request"] is None and hello["client_id"].startswith("c")
            fut = ask_in_thread(broker, make_request(phase=1))
            req = await c.recv("request")
            assert req["phase"] == "grasp" and "touch the object" in req["prompt"] and req["suggested_vacuum"] is True
            assert req["state"]["goal"] == pytest.approx([0.48, 0.2, 0.025]) and len(req["state"]["joints"]) == 6
            await c.send({"type": "answer", "id": req["id"], "target": [0.5, -0.08, 0.047], "vacuum": True})
            ack = await c.recv("ack")
            assert ack == {
                "type": "ack",
                "for": "answer",
                "id": req["id"],
                "accepted": True,
                "reason": None,
                "code": None,
            }
            cancel = await c.recv("cancel")
            assert cancel["reason"] == "answered"
            return fut.result(5)

    res = run(scenario())
    assert isinstance(res, LiveAnswer) and res.vacuum and res.client == "bot"
    assert np.array_equal(res.target, [0.5, -0.08, 0.047]) and 0 <= res.latency_s < 5


BAD = [
    ("{not json", "malformed JSON"),
    ("[1, 2, 3]", "must be a JSON object"),
    ('{"kind": "answer"}', "no string field 'type'"),
    ('{"type": "teleport"}', "unknown message type"),
    ('{"type": "answer", "target": [0.5, 0, 0.1], "vacuum": true}', "needs a string field 'id'"),
    ('{"type": "answer", "id": "nope-1", "target": [0.5, 0, 0.1], "vacuum": true}', "stale request id"),
    ('{"type": "answer", "id": "ID", "target": [NaN, 0, 0.1], "vacuum": true}', "not finite"),
    ('{"type": "answer", "id": "ID", "target": [0.5, Infinity, 0.1], "vacuum": true}', "not finite"),
    ('{"type": "answer", "id": "ID", "target": [0.5, 1e999, 0.1], "vacuum": true}', "not finite"),
    ('{"type": "answer", "id": "ID", "target": [0.5, 0.0, 0.01], "vacuum": true}', "outside the workspace box: z"),
    ('{"type": "answer", "id": "ID", "target": [0.9, 0.0, 0.1], "vacuum": true}', "outside the workspace box: x"),
    ('{"type": "answer", "id": "ID", "target": [0.5, 0.0], "vacuum": true}', "list of 3 numbers"),
    ('{"type": "answer", "id": "ID", "target": [0.5, "a", 0.1], "vacuum": true}', "not a number"),
    ('{"type": "answer", "id": "ID", "target": [0.5, 0.0, 0.1], "vacuum": 1}', "'vacuum' must be true or false"),
    ('{"type": "hello", "protocol": 1, "client": 7}', "'client' and 'name' must be strings"),
    ('{"type": "answer", "id": "ID", "target": [0.5, 1' + "0" * 400 + ', 0.1], "vacuum": true}', "more than 18 digits"),
    (
        '{"type": "answer", "id": "ID", "target": [0.5, 1' + "0" * 5000 + ', 0.1], "vacuum": true}',
        "more than 18 digits",
    ),
    ('{"type": "ping", "x": ' + "[" * 5000 + "]" * 5000 + "}", "nested too deeply"),
    ("x" * 70_000, "larger than"),
]


def test_every_bad_message_is_refused_with_a_reason_and_the_request_survives(served):
    broker, server = served

    async def scenario():
        async with aiohttp.ClientSession() as http:
            c = await connect(http, server)
            fut = ask_in_thread(broker, make_request())
            req = await c.recv("request")
            for text, reason in BAD:
                await c.send(text.replace('"ID"', json.dumps(req["id"])))
                ack = await c.recv("ack")
                assert ack["accepted"] is False and reason in ack["reason"], (text[:60], ack)
            await c.ws.send_bytes(b"\x00\x01")
            ack = await c.recv("ack")
            assert "binary frames" in ack["reason"]
            assert not fut.done()  # nothing above ended or answered the request
            await c.send({"type": "answer", "id": req["id"], "target": [0.5, -0.08, 0.047], "vacuum": True})
            assert (await c.recv("ack"))["accepted"]
            return fut.result(5)

    assert isinstance(run(scenario()), LiveAnswer)
    assert sum(broker.stats.refused.values()) == len(BAD) + 1
    assert set(broker.stats.refused) <= set(REFUSALS) and "internal" not in broker.stats.refused


@pytest.mark.parametrize("version", [2, True, "1", 1.0, None])
def test_a_hello_of_another_protocol_is_refused_and_the_connection_closed(served, version):
    """JSON's `true` is no protocol 1 (Python's True == 1); the client is told why, then disconnected."""
    broker, server = served

    async def scenario():
        async with aiohttp.ClientSession() as http:
            c = await connect(http, server)
            await c.send({"type": "hello", "protocol": version, "client": "test"})
            ack = await c.recv("ack")
            closed = await c.ws.receive(timeout=5)
            return ack, closed

    ack, closed = run(scenario())
    assert ack["accepted"] is False and ack["code"] == "unsupported_protocol" and "not supported" in ack["reason"]
    assert closed.type in (aiohttp.WSMsgType.CLOSE, aiohttp.WSMsgType.CLOSED) and wait_until(
        lambda: broker.client_count == 0
    )


def test_two_clients_race_for_the_claim_first_wins(served):
    broker, server = served

    async def scenario():
        async with aiohttp.ClientSession() as http:
            a, b = await connect(http, server, "browser"), await connect(http, server, "headset")
            fut = ask_in_thread(broker, make_request())
            rid = (await a.recv("request"))["id"]
            await b.recv("request")
            await asyncio.gather(a.send({"type": "claim", "id": rid}), b.send({"type": "claim", "id": rid}))
            acks = [await a.recv("ack"), await b.recv("ack")]
            assert sorted(x["accepted"] for x in acks) == [False, True]
            winner, loser = (a, b) if acks[0]["accepted"] else (b, a)
            assert "claimed by" in acks[[a, b].index(loser)]["reason"]
            await loser.send({"type": "answer", "id": rid, "target": [0.5, 0.0, 0.1], "vacuum": False})
            assert "claimed by" in (await loser.recv("ack"))["reason"]
            await winner.send({"type": "answer", "id": rid, "target": [0.51, 0.0, 0.1], "vacuum": False})
            assert (await winner.recv("ack"))["accepted"]
            assert (await loser.recv("cancel"))["reason"] == "answered"
            return fut.result(5)

    res = run(scenario())
    assert res.target[0] == pytest.approx(0.51)


def test_a_claim_is_released_when_its_client_disconnects(served):
    broker, server = served

    async def scenario():
        async with aiohttp.ClientSession() as http:
            a, b = await connect(http, server), await connect(http, server)
            fut = ask_in_thread(broker, make_request())
            rid = (await a.recv("request"))["id"]
            await a.send({"type": "claim", "id": rid})
            assert (await b.recv("claimed"))["client_id"] is not None
            await a.ws.close()
            assert (await b.recv("claimed"))["client_id"] is None
            await b.send({"type": "answer", "id": rid, "target": [0.5, 0.0, 0.1], "vacuum": False})
            assert (await b.recv("ack"))["accepted"]
            return fut.result(5)

    assert isinstance(run(scenario()), LiveAnswer)


def test_a_reconnecting_client_gets_the_outstanding_request_again(served):
    broker, server = served

    async def scenario():
        async with aiohttp.ClientSession() as http:
            c = await connect(http, server)
            fut = ask_in_thread(broker, make_request(phase=0))
            rid = (await c.recv("request"))["id"]
            await c.ws.close()
            c2 = await connect(http, server)
            hello = c2.hello
            assert hello["request"]["id"] == rid and hello["status"]["waiting"] is True
            await c2.send({"type": "answer", "id": rid, "target": [0.5, -0.08, 0.13], "vacuum": False})
            assert (await c2.recv("ack"))["accepted"]
            return fut.result(5)

    assert isinstance(run(scenario()), LiveAnswer)


def test_timeout_and_skip_end_the_request_without_an_answer(served):
    broker, server = served

    async def scenario():
        async with aiohttp.ClientSession() as http:
            c = await connect(http, server)
            fut = ask_in_thread(broker, make_request(), timeout=0.3)
            req = await c.recv("request")
            assert req["timeout_s"] == 0.3
            assert (await c.recv("cancel"))["reason"] == "timeout"
            timed_out = fut.result(5)
            fut = ask_in_thread(broker, make_request())
            rid = (await c.recv("request"))["id"]
            await c.send({"type": "skip", "id": rid})
            assert (await c.recv("ack"))["accepted"]
            return timed_out, fut.result(5)

    timed_out, skipped = run(scenario())
    assert isinstance(timed_out, NoAnswer) and timed_out.reason == "timeout"
    assert isinstance(skipped, NoAnswer) and skipped.reason == "skipped"
    assert broker.stats.timeouts == 1 and broker.stats.skipped == 1


def test_status_reaches_every_client(served):
    broker, server = served

    async def scenario():
        async with aiohttp.ClientSession() as http:
            a, b = await connect(http, server), await connect(http, server)
            joined = await a.recv("status")  # b connected
            assert joined["clients"] == 2
            broker.publish_status(step=1234, success_rate=0.5, asked=17)
            sa, sb = await a.recv("status"), await b.recv("status")
            assert sa["step"] == sb["step"] == 1234 and sa["asked"] == 17 and sa["clients"] == 2
            await b.ws.close()
            assert (await a.recv("status"))["clients"] == 1

    run(scenario())


def test_token_is_required_to_watch_or_answer(served):
    _broker, server = served
    base = server.url.split("?")[0]

    async def scenario():
        async with aiohttp.ClientSession() as http:
            assert (await http.get(base)).status == 403
            assert (await http.get(base + "?token=wrong")).status == 403
            assert (await http.get(server.url)).status == 200
            with pytest.raises(aiohttp.WSServerHandshakeError) as err:
                await http.ws_connect(server.ws_url.replace(server.token, "wrong"))
            assert err.value.status == 403
            urdf = await http.get(base + "robot/robot.urdf")
            text = await urdf.text()
            assert urdf.status == 200 and "/robot/pkg/example-robot-data/" in text and 'name="tcp"' in text
            mesh = re.search(r'filename="(/robot/pkg/[^"]+\.dae)"', text).group(1)
            assert (await http.get(base.rstrip("/") + mesh)).status == 200
            assert (await http.get(base + "robot/pkg/../../../../etc/passwd")).status == 404
            assert (
                await http.get(base + "robot/pkg/example-robot-data/robots/ur_description/urdf/ur5_robot.urdf")
            ).status == 404

    run(scenario())


def test_one_request_at_a_time_and_close_ends_a_waiting_request(broker):
    fut = ask_in_thread(broker, make_request())
    assert wait_until(lambda: broker.waiting)
    with pytest.raises(RuntimeError, match="already outstanding"):
        broker.request(make_request(), 0.1)
    broker.close()
    res = fut.result(5)
    assert isinstance(res, NoAnswer) and res.reason == "shutdown"


class _LockPausingAfterTheRequest:
    """The broker's lock, which holds the requesting thread just after it first lets go of the lock with a request
    outstanding: where that thread may lose the CPU on a busy machine."""

    def __init__(self, broker):
        self._lock, self._broker = threading.Lock(), broker
        self.paused, self.resume = threading.Event(), threading.Event()

    def acquire(self, blocking=True, timeout=-1):
        return self._lock.acquire(blocking, timeout)

    def release(self):
        self._lock.release()
        if self._broker._pending is not None and not self.paused.is_set():
            self.paused.set()
            self.resume.wait(5)

    __enter__ = acquire

    def __exit__(self, *exc):
        self.release()


def test_a_client_connecting_as_a_request_is_made_sees_it_and_the_waiting_status_together(broker):
    """The request and "waiting" change under one lock: a hello never has the one without the other (a client that
    reconnected in between was told of a request while the status said nothing was waiting)."""
    lock = broker._lock = _LockPausingAfterTheRequest(broker)
    broker._changed = threading.Condition(lock)
    fut = ask_in_thread(broker, make_request())
    assert lock.paused.wait(5)
    hellos = []
    broker.attach(hellos.append)
    lock.resume.set()
    assert hellos[0]["request"] is not None and hellos[0]["status"]["waiting"] is True, hellos[0]["status"]
    broker.close()
    assert fut.result(5).reason == "shutdown"


def test_a_flood_of_bad_messages_does_not_stall_the_trainer(served):
    broker, server = served

    async def scenario():
        async with aiohttp.ClientSession() as http:
            bad, good = await connect(http, server), await connect(http, server)
            fut = ask_in_thread(broker, make_request())
            rid = (await good.recv("request"))["id"]
            for k in range(300):
                await bad.send(BAD[k % len(BAD)][0])
            await good.send({"type": "answer", "id": rid, "target": [0.5, -0.08, 0.047], "vacuum": True})
            return fut.result(5)

    assert isinstance(run(scenario()), LiveAnswer)


def test_the_page_gets_the_configured_arm(broker, tmp_path):
    """The URDF endpoint and the hello serve the arm the trainer runs: the UR10 when it is configured."""
    from mrguide.annotation.server import AnnotationServer
    from mrguide.robot import RobotConfig, load_robot

    (tmp_path / "index.html").write_text("<!doctype html><title>stub</title>")
    server = AnnotationServer(broker, load_robot(RobotConfig(name="ur10")), port=0, web_dir=tmp_path)
    server.start()

    async def scenario():
        async with aiohttp.ClientSession() as http:
            text = await (await http.get(server.url.split("?")[0] + "robot/robot.urdf")).text()
            assert '<robot name="ur10"' in text and 'name="tcp"' in text
            mesh = re.search(r'filename="(/robot/pkg/[^"]+\.dae)"', text).group(1)
            assert "/ur10/" in mesh and (await http.get(server.url.split("?")[0].rstrip("/") + mesh)).status == 200

    try:
        run(scenario())
    finally:
        broker.close()
        server.stop()


def test_a_person_steps_in_with_intervene_unless_a_demonstration_is_already_asked(served):
    broker, server = served

    async def scenario():
        async with aiohttp.ClientSession() as http:
            c = await connect(http, server)
            await c.send({"type": "intervene"})
            first = await c.recv("ack")
            assert wait_until(lambda: broker._intervene is not None)
            taken = broker.take_intervention()
            fut = ask_in_thread(broker, make_request())
            req = await c.recv("request")
            await c.send({"type": "intervene"})  # a demonstration is being asked for already
            second = await c.recv("ack")
            await c.send({"type": "skip", "id": req["id"]})
            fut.result(5)
            return first, taken, second

    first, taken, second = run(scenario())
    assert first["accepted"] and first["for"] == "intervene" and taken.startswith("c")
    assert second["accepted"] is False and second["code"] == "stale" and "already being asked" in second["reason"]
    assert broker.take_intervention() is None and broker.stats.interventions == 1
