"""Placing a mark with clicks on the real page in headless Chromium: on the part, the goal or the table, through
a gizmo arrow, and the Intervene control."""

from __future__ import annotations

import numpy as np
import pytest

from mrguide.annotation.broker import AnnotationBroker, LiveAnswer
from mrguide.annotation.live import hello_fields
from mrguide.annotation.server import AnnotationServer
from mrguide.task import TaskConfig
from tests.annotation.conftest import ask_in_thread, make_request, wait_until
from tests.annotation.test_page import GOAL, OBJ, QUAT


def _click(page, point) -> None:
    """A person's click on what the page shows at robot-frame `point`."""
    px = page.page.evaluate("(p) => window.mrguide.screenOf(p)", list(map(float, point)))
    page.page.mouse.click(px["x"], px["y"])


def test_click_to_place_on_the_part_the_goal_and_the_table(browser, page_served, spec):
    """One click on the part's top puts the pick mark at its centre; on the goal ring the place mark at the goal; on
    the table at that point, at the phase's height; a second click submits. A drag is no click: it orbits."""
    broker, server = page_served
    task = TaskConfig()
    page = browser.open(server.url)
    try:
        fut = ask_in_thread(broker, make_request(1, obj=OBJ, goal=GOAL, quat=QUAT))  # the pick mark (grasp)
        page.wait_request()
        page.wait_robot()
        _click(page, OBJ + [0.004, -0.006, 0.5 * task.object_height])  # a little off the top face's centre
        s = page.wait_state("s.placedOn === 'object'")
        assert s["target"] == pytest.approx([OBJ[0], OBJ[1], task.object_height], abs=1e-4)  # snapped to the centre
        page.click_submit()
        pick = fut.result(10)
        assert isinstance(pick, LiveAnswer) and pick.target == pytest.approx(
            [OBJ[0], OBJ[1], task.object_height], abs=1e-4
        )

        fut = ask_in_thread(broker, make_request(4, obj=OBJ, goal=GOAL, quat=QUAT))  # the place mark (release)
        page.wait_state("s.phase === 'release'")
        _click(page, GOAL + [0.03, 0.0, -GOAL[2] + 0.001])  # on the ring, 3 cm from the goal
        s = page.wait_state("s.placedOn === 'goal'")
        assert s["target"] == pytest.approx([GOAL[0], GOAL[1], task.object_height], abs=1e-4)
        page.press("Enter")
        place = fut.result(10)
        assert place.target == pytest.approx([GOAL[0], GOAL[1], task.object_height], abs=1e-4)

        fut = ask_in_thread(
            broker, make_request(3, obj=OBJ, goal=GOAL, quat=QUAT)
        )  # transport: table point, lift height
        page.wait_state("s.phase === 'transport'")
        spot = np.array([0.42, 0.05, 0.0])
        _click(page, spot)
        s = page.wait_state("s.placedOn === 'table'")
        assert s["target"][:2] == pytest.approx(spot[:2], abs=0.003) and s["target"][2] == pytest.approx(
            task.lift_height
        ), s["target"]
        before = s["target"]
        px = page.page.evaluate("(p) => window.mrguide.screenOf(p)", [0.5, 0.25, 0.0])
        page.page.mouse.move(px["x"], px["y"])
        page.page.mouse.down()
        page.page.mouse.move(px["x"] + 60, px["y"] + 20, steps=5)  # a drag: the camera turns, the target stays
        page.page.mouse.up()
        assert page.state()["target"] == before
        page.skip()
    finally:
        page.close()


def test_exactly_here_puts_the_mark_where_clicked_on_the_part_and_teaches_it(browser, page_served):
    """With Exactly here on (the button, or H), a click on the part's top puts the pick mark at the point clicked, on
    the face, not at the part's centre, and the answer carries `here`; the next request starts with it off."""
    broker, server = page_served
    task = TaskConfig()
    page = browser.open(server.url)
    try:
        fut = ask_in_thread(broker, make_request(1, obj=OBJ, goal=GOAL, quat=QUAT))
        page.wait_request()
        page.wait_robot()
        page.page.click("#here")
        assert page.wait_state("s.here")["here"] is True
        clicked = OBJ + [0.012, -0.008, 0.5 * task.object_height]
        _click(page, clicked)
        s = page.wait_state("s.placedOn === 'object'")
        assert s["target"] == pytest.approx(clicked, abs=1.5e-3)  # where clicked, on the top face
        page.click_submit()
        pick = fut.result(10)
        assert isinstance(pick, LiveAnswer) and pick.here and pick.target == pytest.approx(clicked, abs=1.5e-3)
        fut = ask_in_thread(broker, make_request(1, obj=OBJ, goal=GOAL, quat=QUAT))
        page.wait_state(f"s.requestId && s.requestId !== {pick.request_id!r}")
        assert page.state()["here"] is False
        page.press("h")
        assert page.wait_state("s.here")["here"] is True
        page.skip()
        fut.result(10)
    finally:
        page.close()


def test_the_person_steps_in_with_the_intervene_button_or_the_i_key(browser, page_served):
    """No request outstanding: Intervene (button, or I) asks the trainer to cut the agent's episode; while a
    request is shown the button is off (answer it instead)."""
    broker, _ = page_served
    page = browser.open(page_served[1].url)
    try:
        page.wait_state("s.connected")
        assert not page.page.is_disabled("#intervene")
        page.page.click("#intervene")
        assert wait_until(lambda: broker._intervene is not None)
        assert broker.take_intervention() == page.state()["clientId"]
        assert "Stepping in" in page.text("feedback")
        page.press("i")
        assert wait_until(lambda: broker.take_intervention() is not None)
        fut = ask_in_thread(broker, make_request(1, obj=OBJ, goal=GOAL, quat=QUAT))
        page.wait_request()
        assert page.page.is_disabled("#intervene")
        page.skip()
        fut.result(10)
    finally:
        page.close()


def test_a_click_on_a_gizmo_arrow_places_through_it(browser, page_served):
    """The gizmo's arrows stand over what is behind them (over the goal while the arm holds the part above
    it): a click there, without a drag, places the target on the surface behind, as anywhere else."""
    broker, server = page_served
    page = browser.open(server.url)
    try:
        fut = ask_in_thread(broker, make_request(3, obj=OBJ, goal=GOAL, quat=QUAT))  # transport: a table point
        page.wait_request()
        page.wait_robot()
        before = page.state()["target"]
        h = page.gizmo_handle("X")
        page.page.mouse.click(h["x"], h["y"])
        s = page.wait_state("s.placedOn !== null")
        assert s["placedOn"] in ("table", "goal", "object") and s["target"][:2] != pytest.approx(before[:2], abs=0.01)
        page.skip()
        fut.result(10)
    finally:
        page.close()


def test_the_page_draws_the_selected_part_and_snaps_to_its_top(browser, spec):
    """The hello names the L-bracket: the page draws its two boxes, and a click on its base snaps the pick mark to the
    part's origin at its top (6 cm, the wall's), not the block's."""
    task = TaskConfig(part="l_bracket")
    broker = AnnotationBroker(spec.workspace, hello_fields(spec, task))
    server = AnnotationServer(broker, spec, port=0)
    server.start()
    page = browser.open(server.url)
    try:
        fut = ask_in_thread(broker, make_request(1, obj=OBJ, goal=GOAL, quat=QUAT))
        page.wait_request()
        drawn = page.page.evaluate("() => window.mrguide.part()")
        assert drawn["boxes"] == pytest.approx([0.1, 0.01]) and drawn["height"] == pytest.approx(0.06)
        _click(page, OBJ + [0.02, 0.0, -0.02])  # on the base, beside the wall
        s = page.wait_state("s.placedOn === 'object'")
        assert s["target"] == pytest.approx([OBJ[0], OBJ[1], 0.06], abs=1e-4)
        page.click_submit()
        assert fut.result(10).target == pytest.approx([OBJ[0], OBJ[1], 0.06], abs=1e-4)
    finally:
        page.close()
        broker.close()
        server.stop()
