"""WebXR of the annotation page, with Meta's IWER emulating the headset in headless Chromium.

The page imports IWER when its URL carries `?xr=PROFILE` (web/emulation.js) and installs the emulated
runtime over navigator.xr before it sets up XR; the test then drives the emulated device through
`window.mrguide.xrDevice` (IWER's XRDevice: head pose, controllers, hands) and checks what reaches
the trainer.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from mrguide.annotation.broker import AnnotationBroker, LiveAnswer
from mrguide.annotation.headless import HeadlessBrowser, chromium_path
from mrguide.annotation.live import hello_fields
from mrguide.annotation.server import WEB_DIR, AnnotationServer
from mrguide.robot import load_robot
from mrguide.task import TaskConfig
from tests.annotation.conftest import ask_in_thread, make_request, wait_until

OBJ = np.array([0.52, -0.06, 0.025])
GOAL = np.array([0.46, 0.22, 0.025])
TABLE_HEIGHT = 0.75  # web/emulation.js: the emulated table surface (local-floor, y up)
HEAD = np.array([0.0, 1.6, 0.0])  # IWER's default head position


def placement(state) -> np.ndarray:
    """The page's robot-frame -> XR reference space matrix (three.js stores it column-major)."""
    return np.array(state["xr"]["placement"]).reshape(4, 4).T


def transform(T: np.ndarray, p) -> np.ndarray:
    return (T @ np.append(np.asarray(p, dtype=float), 1.0))[:3]


@pytest.fixture(scope="module")
def browser():
    chromium_path()  # missing pieces are errors, not skips: .ci/run installs chromium, ./run.sh runs npm ci
    assert (WEB_DIR / "node_modules" / "iwer").is_dir(), "run `npm ci` in mrguide/annotation/web (./run.sh does)"
    with HeadlessBrowser(viewport=(960, 600)) as b:  # XR draws every frame: a smaller canvas is faster on SwiftShader
        yield b


@pytest.fixture
def spec():
    return load_robot()


def serve(spec, registration=None):
    broker = AnnotationBroker(spec.workspace, hello_fields(spec, TaskConfig(), registration))
    server = AnnotationServer(broker, spec, port=0)
    server.start()
    return broker, server


RIGHT_TRIGGER = "(v) => window.mrguide.xrDevice.controllers.right.updateButtonValue('trigger', v)"
LEFT_TRIGGER = "(v) => window.mrguide.xrDevice.controllers.left.updateButtonValue('trigger', v)"
RIGHT_PINCH = "(v) => window.mrguide.xrDevice.hands.right.updatePinchValue(v)"
RIGHT_SQUEEZE = "(v) => window.mrguide.xrDevice.controllers.right.updateButtonValue('squeeze', v)"


def press(page, button: str, counted: str = "selects") -> None:
    """A full press of an IWER input (`button`: JS taking the value): press until the page counted its event
    (`counted`: IWER fires `select` or `squeeze` on the press's frame), release until IWER sampled the release.
    IWER samples the buttons once per XR frame: a release not yet sampled when the next press is written is
    overwritten by it, and that press is no edge, no event (the race a busy machine once lost)."""
    n = page.state()["xr"][counted]
    page.page.evaluate(button, 1)
    page.wait_state(f"s.xr.{counted} > {n}")
    f = page.state()["xr"]["frames"]
    page.page.evaluate(button, 0)
    page.wait_state(f"s.xr.frames > {f + 2}")


def test_quest3_immersive_ar_hit_test_and_controller_select(browser, spec, tmp_path):
    broker, server = serve(spec)
    fut = ask_in_thread(broker, make_request(1, obj=OBJ, goal=GOAL))
    page = browser.open(server.url + "&xr=quest3")
    try:
        s = page.wait_request()
        page.wait_robot()
        assert s["xr"]["arSupported"] and page.text("xr-button") == "Enter AR"
        assert "Meta Quest 3" in page.text("emulated")
        xr = page.enter_xr()
        assert xr["mode"] == "immersive-ar" and xr["blendMode"] == "alpha-blend"
        assert xr["transparent"] and xr["hitTest"] and not xr["placed"]

        # Look down at the table: the hit-test reticle appears where the gaze meets it.
        pitch = math.radians(-50)
        page.page.evaluate(f"""() => {{ const d = window.mrguide.xrDevice;
            d.position.set(0, 1.6, 0); d.quaternion.set({math.sin(pitch / 2)}, 0, 0, {math.cos(pitch / 2)}); }}""")
        page.wait_state("s.xr.reticleVisible")
        gaze = np.array([0.0, math.sin(pitch), -math.cos(pitch)])
        hit = HEAD + (TABLE_HEIGHT - HEAD[1]) / gaze[1] * gaze

        # The first select places the robot base there, its +x (toward the workspace) facing the person.
        press(page, RIGHT_TRIGGER)
        s = page.wait_state("s.xr.placed")
        assert s["xr"]["placementSource"] == "hit-test"
        M = placement(s)
        np.testing.assert_allclose(M[:3, 3], hit, atol=1e-3)
        np.testing.assert_allclose(M[:3, 0], [0, 0, 1], atol=1e-6)  # robot x -> toward the person (+z here)
        np.testing.assert_allclose(M[:3, 2], [0, 1, 0], atol=1e-6)  # robot z -> up
        assert s["requestId"] and not fut.done()  # placing is not answering

        # Hold the controller at a point of the workspace and select: that point is the waypoint.
        p_robot = np.array([0.50, 0.05, 0.12])
        w = transform(M, p_robot)
        page.page.evaluate(f"() => window.mrguide.xrDevice.controllers.right.position.set({w[0]}, {w[1]}, {w[2]})")
        page.wait_state(f"s.xr.frames > {s['xr']['frames'] + 2}")
        page.screenshot(tmp_path / "annotation-quest3-ar.png")
        press(page, RIGHT_TRIGGER)
        answer = fut.result(timeout=15)
        assert isinstance(answer, LiveAnswer)
        np.testing.assert_allclose(answer.target, p_robot, atol=1.5e-4)  # 0.1 mm rounding + float32 poses
        assert answer.vacuum is True  # grasp: the suggested vacuum, not toggled
        assert answer.client == "headset"
        s = page.wait_state("s.closed && s.closed.mine")
        np.testing.assert_allclose(s["xr"]["lastSelect"]["robot"], p_robot, atol=1e-4)
    finally:
        page.close()
        broker.close()
        server.stop()


def test_hololens2_profile_falls_back_to_additive_vr_placed_by_registration(browser, spec):
    # The HMD's tracking frame (y up) in the robot base frame (z up), as `mrguide calibrate` writes it.
    yaw = math.radians(30)
    Rz = np.array([[math.cos(yaw), -math.sin(yaw), 0], [math.sin(yaw), math.cos(yaw), 0], [0, 0, 1]])
    Rx = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]])  # hmd y -> base z
    T_base_hmd = np.eye(4)
    T_base_hmd[:3, :3] = Rz @ Rx
    T_base_hmd[:3, 3] = [0.9, -0.3, -0.74]
    broker, server = serve(spec, {"T_base_hmd": T_base_hmd.tolist(), "method": "test", "rms_residual_m": 0.001})
    fut = ask_in_thread(broker, make_request(4, obj=OBJ, goal=GOAL))
    page = browser.open(server.url + "&xr=hololens2")
    try:
        s = page.wait_request()
        page.wait_robot()
        assert not s["xr"]["arSupported"] and s["xr"]["vrSupported"]
        assert page.text("xr-button") == "Enter VR (no AR here)"
        xr = page.enter_xr()
        assert xr["mode"] == "immersive-vr" and xr["blendMode"] == "additive"
        assert xr["transparent"]  # additive display: black background, nothing drawn over the real cell
        assert xr["placed"] and xr["placementSource"] == "registration" and not xr["hitTest"]
        s = page.state()
        np.testing.assert_allclose(placement(s), np.linalg.inv(T_base_hmd), atol=1e-6)

        # A hand pinch (HoloLens has no controllers) near a point of the workspace marks it.
        p_robot = np.array([0.47, 0.10, 0.20])
        w = transform(np.linalg.inv(T_base_hmd), p_robot)
        page.page.evaluate(f"() => window.mrguide.xrDevice.hands.right.position.set({w[0]}, {w[1]}, {w[2]})")
        page.wait_state(f"s.xr.frames > {s['xr']['frames'] + 2}")
        press(page, RIGHT_PINCH)
        answer = fut.result(timeout=15)
        assert isinstance(answer, LiveAnswer) and answer.client == "headset"
        assert answer.vacuum is False  # release: vacuum off
        s = page.state()
        sel = s["xr"]["lastSelect"]
        assert sel["hand"] is True
        # The pinch point (between thumb and index tips) is near the tracked hand, and what was sent is
        # that point in the robot frame, clamped into the box, at 0.1 mm.
        assert np.linalg.norm(np.array(sel["robot"]) - p_robot) < 0.2
        np.testing.assert_allclose(sel["robot"], transform(T_base_hmd, sel["world"]), atol=1e-5)
        expected = np.clip(sel["robot"], spec.workspace.lo, spec.workspace.hi)
        np.testing.assert_allclose(answer.target, expected, atol=6e-5)
        assert spec.workspace.contains(answer.target)
    finally:
        page.close()
        broker.close()
        server.stop()


def test_quest3_without_ar_falls_back_to_vr_and_places_in_front(browser, spec):
    broker, server = serve(spec)
    fut = ask_in_thread(broker, make_request(0, obj=OBJ, goal=GOAL))
    page = browser.open(server.url + "&xr=quest3-vr")
    try:
        page.wait_request()
        xr = page.enter_xr()
        assert xr["mode"] == "immersive-vr" and xr["blendMode"] == "opaque" and not xr["transparent"]
        s = page.wait_state("s.xr.placed")
        assert s["xr"]["placementSource"] == "default"  # neither registration nor hit-test
        M = placement(s)
        assert M[1, 3] == pytest.approx(HEAD[1] - 0.7, abs=1e-6) and M[2, 3] == pytest.approx(-0.8, abs=1e-6)
        p_robot = np.array([0.40, -0.10, 0.25])
        w = transform(M, p_robot)
        page.page.evaluate(f"() => window.mrguide.xrDevice.controllers.left.position.set({w[0]}, {w[1]}, {w[2]})")
        page.wait_state(f"s.xr.frames > {s['xr']['frames'] + 2}")
        press(page, LEFT_TRIGGER)
        answer = fut.result(timeout=15)
        assert isinstance(answer, LiveAnswer)
        np.testing.assert_allclose(answer.target, p_robot, atol=1.5e-4)
        assert answer.vacuum is False
        page.page.evaluate("() => window.mrguide.exitXR()")
        s = page.wait_state("!s.xr.presenting")
        np.testing.assert_allclose(placement(s), [[1, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, 0], [0, 0, 0, 1]], atol=1e-9)
    finally:
        page.close()
        broker.close()
        server.stop()


def test_squeeze_steps_in_without_a_request_and_toggles_the_vacuum_with_one(browser, spec):
    """In the headset the grip does what the Intervene button does while no request is open, and
    toggles the vacuum of the answer while one is."""
    broker, server = serve(spec)
    page = browser.open(server.url + "&xr=quest3-vr")
    try:
        page.wait_state("s.connected")
        page.enter_xr()
        page.wait_state("s.xr.placed")
        press(page, RIGHT_SQUEEZE, "squeezes")
        assert wait_until(lambda: broker._intervene is not None, timeout=15)
        assert broker.take_intervention() == page.state()["clientId"]

        fut = ask_in_thread(broker, make_request(1, obj=OBJ, goal=GOAL))  # grasp: vacuum suggested on
        s = page.wait_request()
        assert s["vacuum"] is True
        press(page, RIGHT_SQUEEZE, "squeezes")
        s = page.wait_state("s.vacuum === false")
        M = placement(s)
        p_robot = np.array([0.50, -0.05, 0.10])
        w = transform(M, p_robot)
        page.page.evaluate(f"() => window.mrguide.xrDevice.controllers.right.position.set({w[0]}, {w[1]}, {w[2]})")
        page.wait_state(f"s.xr.frames > {s['xr']['frames'] + 2}")
        press(page, RIGHT_TRIGGER)
        answer = fut.result(timeout=15)
        assert isinstance(answer, LiveAnswer) and answer.vacuum is False  # toggled, not the suggestion
        assert broker.take_intervention() is None  # a squeeze during a request does not step in
    finally:
        page.close()
        broker.close()
        server.stop()


def aim(page, controller: str, origin_world: np.ndarray, at_world: np.ndarray) -> None:
    """Hold an IWER controller at `origin_world`, its target ray (-z) pointing at `at_world`."""
    a = np.array([0.0, 0.0, -1.0])
    d = (at_world - origin_world) / np.linalg.norm(at_world - origin_world)
    q = np.append(np.cross(a, d), 1.0 + a @ d)  # the shortest rotation taking -z onto d (x, y, z, w)
    q /= np.linalg.norm(q)
    o = origin_world
    page.page.evaluate(f"""() => {{ const c = window.mrguide.xrDevice.controllers.{controller};
        c.position.set({o[0]}, {o[1]}, {o[2]}); c.quaternion.set({q[0]}, {q[1]}, {q[2]}, {q[3]}); }}""")


def test_a_controller_outside_the_workspace_points_and_its_ray_places_the_target(browser, spec):
    """Held outside the workspace box, a controller's select places the target where its ray meets the part
    (snapped to the centre, at the phase's height), as a desktop click does; no clamped tip point."""
    task = TaskConfig()
    broker, server = serve(spec)
    fut = ask_in_thread(broker, make_request(1, obj=OBJ, goal=GOAL))  # grasp
    page = browser.open(server.url + "&xr=quest3-vr")
    try:
        page.wait_request()
        page.enter_xr()
        s = page.wait_state("s.xr.placed")
        M = placement(s)
        origin = np.array([0.95, -0.06, 0.60])  # beyond the workspace box, above and in front of the part
        assert not spec.workspace.contains(origin)
        top = np.array([OBJ[0] + 0.004, OBJ[1] - 0.006, task.object_height])  # a little off the top face's centre
        aim(page, "right", transform(M, origin), transform(M, top))
        page.wait_state(f"s.xr.frames > {s['xr']['frames'] + 2}")
        press(page, RIGHT_TRIGGER)
        answer = fut.result(timeout=15)
        assert isinstance(answer, LiveAnswer) and answer.client == "headset"
        np.testing.assert_allclose(answer.target, [OBJ[0], OBJ[1], task.object_height], atol=1.5e-4)
        assert page.state()["xr"]["lastSelect"]["on"] == "object"
    finally:
        page.close()
        broker.close()
        server.stop()
