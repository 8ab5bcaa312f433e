"""The annotation server against a hostile client: never a 500, foreign origins refused, claims that expire,
idle connections closed, tokens and keys checked before serving, a URL a headset can reach."""

from __future__ import annotations

import asyncio
import socket
import subprocess
import time

import aiohttp
import pytest

from mrguide.annotation import server as server_module
from mrguide.annotation.broker import AnnotationBroker, LiveAnswer
from mrguide.annotation.server import AnnotationServer, ServerError
from mrguide.robot import load_robot
from tests.annotation.conftest import ask_in_thread, connect, make_request


def run(coro):
    return asyncio.run(coro)


def _raw_get(server: AnnotationServer, target: bytes, headers: bytes = b"") -> int:
    """The status of a hand-written HTTP request (aiohttp's client would refuse to send most of these)."""
    with socket.create_connection(("127.0.0.1", server.port), timeout=5) as s:
        s.sendall(
            b"GET "
            + target
            + b" HTTP/1.1\r\nHost: 127.0.0.1:%d\r\n" % server.port
            + headers
            + b"Connection: close\r\n\r\n"
        )
        reply = s.recv(4096)
    return int(reply.split(b" ", 2)[1])


@pytest.mark.parametrize(
    "target",
    [
        b"/?token=%C3%A9t%C3%A9",
        b"/ws?token=%F0%9F%A4%96",
        b"/?token=%ED%A0%80",
        b"/robot/pkg/a%00b.dae",
        b"/robot/pkg/" + b"x" * 300 + b".dae",
        b"/static/index.html",
        b"/static/package.json",
        b"/static/%2e%2e%2fserver.py",
        b"/static/app.js%00.js",
    ],
)
def test_what_a_client_sends_never_reaches_a_500(served, target):
    _, server = served
    status = _raw_get(server, target)
    assert status in (400, 403, 404), (target, status)


def test_the_page_itself_is_only_behind_the_token_its_scripts_are_static(served, tmp_path):
    _, server = served
    (server.web_dir / "app.js").write_text("export {};")
    base = server.url.split("?")[0]

    async def scenario():
        async with aiohttp.ClientSession() as http:
            return [(await http.get(base + path)).status for path in ("static/index.html", "static/app.js", "?token=x")]

    assert run(scenario()) == [404, 200, 403]


def test_a_foreign_origin_or_host_is_refused(served):
    _, server = served
    good = f"http://127.0.0.1:{server.port}"

    async def status(headers):
        async with aiohttp.ClientSession() as http:
            try:
                async with http.ws_connect(server.ws_url, headers=headers) as ws:
                    await ws.close()
                    return 101
            except aiohttp.WSServerHandshakeError as exc:
                return exc.status

    assert run(status({"Origin": good})) == 101  # the page's own origin
    assert run(status({})) == 101  # a non-browser client (the bot) sends none
    assert run(status({"Origin": "http://evil.example"})) == 403
    assert run(status({"Origin": f"https://127.0.0.1:{server.port}"})) == 403  # another scheme is another origin
    assert (
        run(status({"Host": f"rebound.example:{server.port}", "Origin": f"http://rebound.example:{server.port}"}))
        == 403
    )
    assert _raw_get(server, b"/?token=" + server.token.encode(), b"Origin: http://evil.example\r\n") == 403


def test_a_claim_expires_when_its_client_goes_quiet_and_the_request_is_open_again(tmp_path):
    spec = load_robot()
    broker = AnnotationBroker(spec.workspace, {}, claim_timeout_s=0.3)
    (tmp_path / "index.html").write_text("<!doctype html>")
    server = AnnotationServer(broker, spec, port=0, web_dir=tmp_path)
    server.start()

    async def scenario():
        async with aiohttp.ClientSession() as http:
            quiet, other = await connect(http, server), await connect(http, server)
            fut = ask_in_thread(broker, make_request())
            req = await quiet.recv("request")
            await other.recv("request")
            await quiet.send({"type": "claim", "id": req["id"]})
            assert (await other.recv("claimed"))["client_id"] is not None
            released = await other.recv("claimed", timeout=5)  # nothing from the claimant for 0.3 s
            assert released["client_id"] is None and released["reason"] == "expired"
            await other.send({"type": "answer", "id": req["id"], "target": [0.5, -0.08, 0.047], "vacuum": True})
            assert (await other.recv("ack"))["accepted"]
            return fut.result(5)

    try:
        res = run(scenario())
    finally:
        broker.close()
        server.stop()
    assert isinstance(res, LiveAnswer) and broker.stats.claims_expired == 1


def test_a_claimant_that_pings_keeps_its_claim(served):
    broker, server = served
    broker.claim_timeout_s = 0.4

    async def scenario():
        async with aiohttp.ClientSession() as http:
            c = await connect(http, server)
            fut = ask_in_thread(broker, make_request())
            req = await c.recv("request")
            await c.send({"type": "claim", "id": req["id"]})
            for _ in range(6):  # 1.2 s, three claim timeouts, alive all along
                await asyncio.sleep(0.2)
                await c.send({"type": "ping"})
            await c.send({"type": "answer", "id": req["id"], "target": [0.5, -0.08, 0.047], "vacuum": True})
            return fut.result(5)

    assert isinstance(run(scenario()), LiveAnswer) and broker.stats.claims_expired == 0


def test_an_answer_is_acknowledged_once_the_trainer_has_recorded_it(served):
    broker, server = served

    async def scenario():
        async with aiohttp.ClientSession() as http:
            c = await connect(http, server)
            fut = ask_in_thread(broker, make_request(), acknowledge=False)
            req = await c.recv("request")
            await c.send({"type": "answer", "id": req["id"], "target": [0.5, -0.08, 0.047], "vacuum": True})
            answer = fut.result(5)
            assert (await c.recv("cancel"))["reason"] == "answered"
            with pytest.raises(asyncio.TimeoutError):
                await c.recv("ack", timeout=0.5)  # not yet: nothing is on disk
            broker.acknowledge(answer)  # the trainer, after the annotation log's fsync
            return await c.recv("ack")

    ack = run(scenario())
    assert ack["accepted"] and ack["for"] == "answer"


def test_an_idle_connection_is_closed(broker, tmp_path, monkeypatch):
    monkeypatch.setattr(server_module, "KEEPALIVE_S", 0.3)
    (tmp_path / "index.html").write_text("<!doctype html>")
    server = AnnotationServer(broker, load_robot(), port=0, web_dir=tmp_path)
    server.start()
    try:
        with socket.create_connection(("127.0.0.1", server.port), timeout=5) as s:
            t0 = time.monotonic()
            assert s.recv(1) == b""  # closed by the server, nothing sent either way
            assert time.monotonic() - t0 < 4
    finally:
        server.stop()


@pytest.mark.parametrize("token", ["x", "short-token", "ünïcödé-token-long-enough"])
def test_a_token_too_short_or_not_ascii_is_refused_before_serving(broker, token):
    with pytest.raises(ServerError, match="at least 16 printable ASCII characters"):
        AnnotationServer(broker, load_robot(), port=0, token=token)


def test_the_printed_url_names_a_reachable_host(broker):
    every = AnnotationServer(broker, load_robot(), host="0.0.0.0", port=8765)
    assert every.url.startswith(f"http://{server_module.reachable_address()}:8765/?token=")
    assert AnnotationServer(broker, load_robot(), host="::1", port=8765).url.startswith("http://[::1]:8765/?token=")
    assert AnnotationServer(broker, load_robot(), host="127.0.0.1", port=8765).url.startswith("http://127.0.0.1:8765/")


def test_an_encrypted_key_fails_at_once_instead_of_prompting(broker, tmp_path):
    key, cert = tmp_path / "key.pem", tmp_path / "cert.pem"
    subprocess.run(
        [
            "openssl",
            "req",
            "-x509",
            "-newkey",
            "rsa:2048",
            "-keyout",
            str(key),
            "-out",
            str(cert),
            "-days",
            "1",
            "-subj",
            "/CN=mrguide",
            "-passout",
            "pass:secret",
        ],
        check=True,
        capture_output=True,
        stdin=subprocess.DEVNULL,
    )
    t0 = time.monotonic()
    with pytest.raises(ServerError, match="the TLS key is encrypted"):
        AnnotationServer(broker, load_robot(), port=0, cert=cert, key=key)
    assert time.monotonic() - t0 < 10


def test_the_page_assets_are_the_module_graph_of_the_page():
    """What the wheel ships: every npm file the page's scripts import (through the import map and the modules' own
    imports), with the packages' licences, and nothing else of node_modules."""
    from mrguide.annotation.page_assets import import_map, module_files
    from mrguide.annotation.server import WEB_DIR

    files = {str(p.relative_to(WEB_DIR.resolve() / "node_modules")) for p in module_files(WEB_DIR)}
    assert {
        "three/build/three.module.js",
        "three/build/three.core.js",
        "urdf-loader/src/URDFLoader.js",
        "three/examples/jsm/controls/TransformControls.js",
        "three/examples/jsm/loaders/ColladaLoader.js",
        "iwer/build/iwer.module.js",
        "three/LICENSE",
        "iwer/LICENSE",
    } <= files
    assert not any(f.endswith((".ts", ".md", ".json")) or "/test" in f for f in files) and len(files) < 40
    assert import_map(WEB_DIR)["three"] == "/node_modules/three/build/three.module.js"
