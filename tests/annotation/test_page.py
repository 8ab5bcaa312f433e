"""The real annotation page in headless Chromium (SwiftShader WebGL), against a real broker and server.

A thread plays the trainer (`broker.request` blocks as it does in training); the page is driven with the
mouse and the keyboard like a person would, and the test checks what reaches the trainer.
"""

from __future__ import annotations

import asyncio
import json
import os
import re
import shutil
import threading
from pathlib import Path

import aiohttp
import numpy as np
import pytest

from mrguide.annotation.broker import AnnotationBroker, LiveAnswer, NoAnswer
from mrguide.annotation.protocol import PROMPTS
from mrguide.annotation.server import WEB_DIR, AnnotationServer, ServerError
from tests.annotation.conftest import ask_in_thread, make_request

REPO = Path(__file__).resolve().parents[2]
OBJ = np.array([0.52, -0.06, 0.025])
GOAL = np.array([0.46, 0.22, 0.025])
QUAT = np.array([0.0, 0.0, 0.2588190, 0.9659258])  # 30 degrees about z


def screen_delta(page, p, dp) -> tuple[float, float]:
    """Screen pixels (dx, dy) between robot-frame points p and p + dp, as the page's camera shows them."""
    a, b = page.page.evaluate(
        "([p, q]) => [window.mrguide.screenOf(p), window.mrguide.screenOf(q)]",
        [list(map(float, p)), list(map(float, np.add(p, dp)))],
    )
    return b["x"] - a["x"], b["y"] - a["y"]


def _shows_the_request(page, s, req, spec) -> np.ndarray:
    """What the page shows for `req` (with the status published); returns the gizmo's start."""
    # What is asked, in words, and the phase.
    assert page.text("phase") == "Phase 2/5 · grasp"
    assert page.text("prompt") == PROMPTS[1]
    assert s["vacuum"] is True  # suggested for grasp
    # The arm: URDF and meshes loaded, the requested joint values applied, and its TCP link where
    # Pinocchio puts it (frames and joint order agree between the page and the trainer).
    robot = page.wait_robot()
    assert robot["meshErrors"] == 0
    for name, q in zip(spec.joint_names, spec.q_home):
        assert robot["joints"][name] == pytest.approx(q, abs=1e-9)
    np.testing.assert_allclose(robot["tcp"], req.tcp, atol=1e-4)
    # The gizmo starts at the TCP (clamped into the box), not at any answer.
    start = np.array(s["target"])
    np.testing.assert_allclose(start, np.clip(req.tcp, spec.workspace.lo, spec.workspace.hi), atol=1e-4)
    # Training status.
    page.wait_state("s.status.step === 3120")
    assert page.text("st-step") == "3120 / 20000"
    assert page.text("st-lambda") == "0.775"
    assert page.text("st-success") == "35 %"
    assert page.text("st-asked") == "212 / 1930"
    assert page.text("st-robot") == "5.2 min, 80 resets, 9 probes"  # the session's cost beside the marks
    assert page.text("st-grasp") == "x -37, y 2 mm from the part's centre · 1 corrections"  # what to correct
    # No headset in plain headless Chromium: the XR button says so instead of failing later.
    assert page.page.is_disabled("#xr-button")
    assert "headset" in page.text("xr-message").lower() or "webxr" in page.text("xr-message").lower()
    assert s["claimedBy"] is None  # nobody has claimed it yet
    return start


def _drag_to_the_part(page, start, spec) -> np.ndarray:
    """The gizmo dragged with the mouse along -y, then down; returns where it ends."""
    # Drag the gizmo's Y arrow with the mouse toward the object (-y), as far on screen as 17 cm there.
    after_y = np.array(page.drag_gizmo("Y", *screen_delta(page, start, [0, -0.17, 0])))
    assert after_y[1] < start[1] - 0.08, (start, after_y)  # moved along -y by a visible amount
    np.testing.assert_allclose(after_y[[0, 2]], start[[0, 2]], atol=2e-4)  # and only along y
    # Then down along z toward the object's top, dragging the Z arrow.
    after_z = np.array(page.drag_gizmo("Z", *screen_delta(page, after_y, [0, 0, -0.25])))
    assert after_z[2] < after_y[2] - 0.1, (after_y, after_z)
    np.testing.assert_allclose(after_z[:2], after_y[:2], atol=2e-4)
    assert spec.workspace.contains(after_z)
    assert page.state()["claimedBy"] == page.state()["clientId"]  # editing claims the request
    return after_z


def _keys_move_the_target(page, after_z) -> np.ndarray:
    """The keyboard's moves and the vacuum toggle; returns the target the page shows and will send."""
    # Keyboard: PageDown 5 mm down, Shift+PageUp 1 mm up, an arrow 5 mm along one table axis, V toggles.
    page.press("PageDown")
    t1 = np.array(page.state()["target"])
    np.testing.assert_allclose(t1 - after_z, [0, 0, -0.005], atol=1e-9)
    page.press("Shift+PageUp")
    t2 = np.array(page.state()["target"])
    np.testing.assert_allclose(t2 - t1, [0, 0, 0.001], atol=1e-9)
    axis, sign = page.page.evaluate("() => window.mrguide.viewAxes().right")
    page.press("ArrowRight")
    t3 = np.array(page.state()["target"])
    step = np.zeros(3)
    step[axis] = 0.005 * sign
    np.testing.assert_allclose(t3 - t2, step, atol=1e-9)
    page.press("v")
    assert page.state()["vacuum"] is False
    page.press("V")
    assert page.state()["vacuum"] is True
    # The numbers shown are the numbers that will be sent.
    shown = [float(page.text(k)) / 1000 for k in ("tx", "ty", "tz")]
    np.testing.assert_allclose(shown, t3, atol=1e-12)
    return t3


def test_page_shows_request_drag_keys_and_submit(browser, page_served, spec, tmp_path):
    broker, server = page_served
    req = make_request(1, obj=OBJ, goal=GOAL, quat=QUAT)
    fut = ask_in_thread(broker, req)
    broker.publish_status(
        step=3120,
        total_steps=20000,
        episode=71,
        success_rate=0.35,
        asked=212,
        reused=1930,
        remarks=3,
        skipped=1,
        fallbacks=0,
        probes=9,
        robot_s=312.0,
        resets=80,
        corrections=1,
        grasp=[-0.037, 0.002, 0.02],
        **{"lambda": 0.775},
    )
    page = browser.open(server.url)
    try:
        s = page.wait_request()
        start = _shows_the_request(page, s, req, spec)
        after_z = _drag_to_the_part(page, start, spec)
        t3 = _keys_move_the_target(page, after_z)

        page.wait_drawn()
        shot = page.screenshot(tmp_path / "annotation-page.png")
        assert shot.stat().st_size > 20_000
        if os.environ.get("MRGUIDE_UPDATE_SCREENSHOT") == "1":
            shutil.copyfile(shot, REPO / "docs" / "annotation-page.png")

        assert page.text("st-cycle") == "–"  # training: no cycle; a learning cell's status names its cycle
        broker.publish_status(cycle=4, version=2)
        page.wait_state("s.status.cycle === 4")
        assert page.text("st-cycle") == "4 · v2"

        page.click_submit()
        answer = fut.result(timeout=15)
        assert isinstance(answer, LiveAnswer)
        np.testing.assert_allclose(answer.target, t3, atol=1e-12)
        assert answer.vacuum is True
        assert answer.client == "browser"
        assert spec.workspace.contains(answer.target)
        s = page.wait_state("s.closed && s.closed.mine")
        assert s["requestId"] is None and s["answers"] == 1
        assert "accepted" in page.text("feedback")
        assert page.page.is_disabled("#submit")
    finally:
        page.close()


def test_target_is_confined_to_the_workspace(browser, page_served, spec):
    broker, server = page_served
    fut = ask_in_thread(broker, make_request(0, obj=OBJ, goal=GOAL, quat=QUAT))
    page = browser.open(server.url)
    try:
        s = page.wait_request()
        lo, hi = spec.workspace.lo, spec.workspace.hi
        # Dragging the gizmo far below the table stops at the floor of the box.
        after = page.drag_gizmo("Z", *screen_delta(page, s["target"], [0, 0, -0.6]))
        assert after[2] == pytest.approx(lo[2], abs=1e-12)
        np.testing.assert_allclose(after[:2], s["target"][:2], atol=2e-4)
        assert page.set_target([2.0, -3.0, -1.0]) == pytest.approx([hi[0], lo[1], lo[2]])
        for _ in range(3):  # nudging past the floor of the box stays on it
            page.press("PageDown")
        assert page.state()["target"][2] == pytest.approx(lo[2])
        assert page.state()["vacuum"] is False  # approach: vacuum off
        page.press("Enter")
        answer = fut.result(timeout=15)
        assert isinstance(answer, LiveAnswer)
        np.testing.assert_allclose(answer.target, [hi[0], lo[1], lo[2]], atol=1e-12)
    finally:
        page.close()


def test_skip_key_and_deadline_countdown(browser, page_served, spec):
    broker, server = page_served
    fut = ask_in_thread(broker, make_request(3, obj=OBJ, goal=GOAL, quat=QUAT), timeout=60.0)
    page = browser.open(server.url)
    try:
        page.wait_request()
        page.wait_js("() => /closes in \\d+ s/.test(document.getElementById('countdown').textContent)")
        page.press("s")
        result = fut.result(timeout=15)
        assert isinstance(result, NoAnswer) and result.reason == "skipped"
        page.wait_state("s.closed && s.closed.reason === 'skipped'")
        assert "skipped" in page.text("prompt")
    finally:
        page.close()


def test_claimed_by_another_client(browser, page_served, spec):
    broker, server = page_served
    fut = ask_in_thread(broker, make_request(2, obj=OBJ, goal=GOAL, quat=QUAT))
    page = browser.open(server.url)
    page_saw_claim = threading.Event()

    async def other_client() -> None:
        async with aiohttp.ClientSession() as session:
            ws = await session.ws_connect(server.ws_url)
            await ws.send_json({"type": "hello", "protocol": 1, "client": "bot"})
            hello = await ws.receive_json()
            rid = hello["request"]["id"]
            await ws.send_json({"type": "claim", "id": rid})
            await asyncio.to_thread(page_saw_claim.wait, 20)  # the test thread checks the page meanwhile
            await ws.send_json({"type": "answer", "id": rid, "target": [0.5, 0.0, 0.2], "vacuum": True})
            await asyncio.wait_for(_until_cancel(ws), 10)

    # Playwright's sync API belongs to this thread: the other client runs in its own.
    other = threading.Thread(target=lambda: asyncio.run(other_client()), daemon=True)
    try:
        page.wait_request()
        other.start()
        page.wait_state("s.claimedBy && s.claimedBy !== s.clientId")
        assert "Claimed by" in page.text("claim")
        assert page.page.is_disabled("#submit") and page.page.is_disabled("#skip")
        assert page.submit() is False  # the hook refuses as the button does
        page_saw_claim.set()
        result = fut.result(timeout=15)
        assert isinstance(result, LiveAnswer) and result.client == "bot"
        page.wait_state("s.closed && s.closed.reason === 'answered' && !s.closed.mine")
        assert "answered by another client" in page.text("prompt")
    finally:
        page_saw_claim.set()
        other.join(timeout=10)
        page.close()


async def _until_cancel(ws) -> None:
    async for msg in ws:
        if msg.type is aiohttp.WSMsgType.TEXT and msg.json().get("type") == "cancel":
            return


def test_refusal_reason_is_shown(browser, page_served, spec):
    """An answer to a request that has closed meanwhile: the server's reason reaches the person.

    The `cancel` is held back on the wire (playwright's WebSocket routing), so the page still shows the
    request after the trainer timed it out: exactly what a slow network does.
    """
    broker, server = page_served
    dropped: list[str] = []

    def hold_back_cancels(page) -> None:
        def handler(ws) -> None:
            server_side = ws.connect_to_server()

            def from_server(message) -> None:
                if isinstance(message, str) and json.loads(message).get("type") == "cancel":
                    dropped.append(message)
                    return
                ws.send(message)

            server_side.on_message(from_server)

        page.route_web_socket(re.compile(r".*/ws\?token=.*"), handler)

    page = browser.open(server.url, setup=hold_back_cancels)
    try:
        page.wait_state("s.connected")
        fut = ask_in_thread(broker, make_request(1, obj=OBJ, goal=GOAL, quat=QUAT), timeout=1.0)
        s = page.wait_request()
        result = fut.result(timeout=15)
        assert isinstance(result, NoAnswer) and result.reason == "timeout"
        assert page.state()["requestId"] == s["requestId"]  # the page never heard of the timeout
        page.click_submit()
        s = page.wait_state("s.lastAck && s.lastAck.for === 'answer' && !s.lastAck.accepted")
        assert s["lastAck"]["reason"].startswith("stale request id")
        assert page.text("feedback").startswith("Refused: stale request id")
        assert not page.page.is_disabled("#submit")  # the person may try again (or wait for the next)
        assert broker.stats.refused["stale"] == 1
        assert dropped, "the cancel should have been held back"
    finally:
        page.close()


def test_reconnect_after_reload_and_server_restart(browser, page_served, spec):
    broker, server = page_served
    fut = ask_in_thread(broker, make_request(1, obj=OBJ, goal=GOAL, quat=QUAT))
    page = browser.open(server.url)
    try:
        s = page.wait_request()
        rid = s["requestId"]
        marked = page.set_target([0.5, -0.06, 0.06])
        # A reload mid-request: the new page gets the outstanding request in its hello.
        page.reload()
        s = page.wait_request(rid)
        assert s["clientId"] != "c1"
        # The server goes away and comes back on the same port: the page reconnects by itself (backoff)
        # and keeps the person's mark.
        marked = page.set_target([0.51, -0.05, 0.07])
        port, token = server.port, server.token
        server.stop()
        page.wait_state("!s.connected")
        assert "reconnecting" in page.text("conn")
        server2 = AnnotationServer(broker, spec, port=port, token=token)
        server2.start()
        try:
            s = page.wait_state(f"s.connected && s.reconnects >= 1 && s.requestId === '{rid}'", timeout_s=30)
            assert s["target"] == marked
            page.press("Enter")
            answer = fut.result(timeout=15)
            assert isinstance(answer, LiveAnswer)
            np.testing.assert_allclose(answer.target, marked, atol=1e-12)
        finally:
            broker.close()
            server2.stop()
    finally:
        page.close()


SERVE_INSTALLED = """
import sys
import mrguide.annotation.server as s
from mrguide.annotation.broker import AnnotationBroker
from mrguide.annotation.live import hello_fields
from mrguide.robot import load_robot
from mrguide.task import TaskConfig
spec = load_robot()
server = s.AnnotationServer(AnnotationBroker(spec.workspace, hello_fields(spec, TaskConfig())), spec, port=0)
print(s.WEB_DIR, server.start(), flush=True)
sys.stdin.read()
"""


def test_a_plain_wheel_serves_a_working_page(browser, tmp_path):
    """`pip install .` carries the page's scripts: the wheel, installed apart from the checkout, serves a page that
    loads and draws the arm in Chromium."""
    import subprocess
    import sys

    from tests.conftest import build_wheel

    wheel = build_wheel(tmp_path)
    site = tmp_path / "site"
    subprocess.run(
        [sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target", str(site), str(wheel)],
        check=True,
        capture_output=True,
        timeout=300,
    )
    proc = subprocess.Popen(
        [sys.executable, "-c", SERVE_INSTALLED],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        env={**os.environ, "PYTHONPATH": str(site)},
        cwd=tmp_path,
    )
    try:
        web_dir, url = proc.stdout.readline().split()
        assert Path(web_dir).is_relative_to(site)  # the installed copy, not the checkout
        page = browser.open(url)
        try:
            assert page.wait_robot()["loaded"]
        finally:
            page.close()
    finally:
        proc.stdin.close()
        proc.wait(10)


def test_a_server_without_the_page_scripts_refuses_to_start_saying_how_to_get_them(tmp_path, spec):
    web = tmp_path / "web"
    shutil.copytree(WEB_DIR, web, ignore=shutil.ignore_patterns("node_modules"))
    server = AnnotationServer(AnnotationBroker(spec.workspace, {}), spec, port=0, web_dir=web)
    with pytest.raises(ServerError, match=r"needs .*node_modules.*which is not there.*npm ci"):
        server.start()
