"""Drive the annotation page in headless Chromium: for the browser tests and the annotation benchmark.

Uses the `playwright` Python package (a dev dependency, imported only here) with Debian's `chromium`
through `executable_path`: never `playwright install`, which downloads a browser of its own. WebGL runs
on SwiftShader (ANGLE's CPU renderer), so no GPU or display is needed.

    with HeadlessBrowser() as browser:
        page = browser.open(server.url)            # append "&xr=quest3" to emulate a headset (IWER)
        state = page.wait_request()                # the page shows a request
        page.drag_gizmo("X", 60, 0)                # a real mouse drag on the gizmo's X arrow
        page.click_submit()

The page's test hook (`window.mrguide`, documented at the top of web/app.js) is what `state()`,
`set_target()` and `gizmo_handle()` call.
"""

from __future__ import annotations

import os
import shutil
import tempfile
import time
from pathlib import Path
from typing import Any

from mrguide.task import Phase

#: Chromium flags for a root user in a container without a GPU or display.
CHROMIUM_ARGS = (
    "--no-sandbox",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--disable-dev-shm-usage",
    "--disable-quic",
    "--no-first-run",
    "--no-default-browser-check",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--disable-extensions",
    "--disable-background-timer-throttling",
    "--disable-renderer-backgrounding",
    "--disable-backgrounding-occluded-windows",
)


class HeadlessError(RuntimeError):
    """No usable Chromium, or the page did not reach a state in time."""


def chromium_path() -> str:
    """Debian's chromium (or $MRGUIDE_CHROMIUM); a clear error when it is missing."""
    candidates = [
        os.environ.get("MRGUIDE_CHROMIUM"),
        "/usr/bin/chromium",
        shutil.which("chromium"),
        shutil.which("chromium-browser"),
    ]
    for c in candidates:
        if c and Path(c).is_file() and os.access(c, os.X_OK):
            return c
    raise HeadlessError("chromium not found: `apt-get install chromium` (Debian) or set MRGUIDE_CHROMIUM")


class HeadlessBrowser:
    """One headless Chromium with a fresh profile; `open(url)` gives an `AnnotationPage`."""

    def __init__(self, executable: str | None = None, viewport: tuple[int, int] = (1280, 800), timeout_s: float = 30.0):
        try:
            from playwright.sync_api import sync_playwright
        except ImportError as exc:  # a dev dependency
            raise HeadlessError("the `playwright` package is needed: pip install -e '.[dev]'") from exc
        self._profile = tempfile.mkdtemp(prefix="mrguide-chromium-")
        self._pw = sync_playwright().start()
        try:
            self.context = self._pw.chromium.launch_persistent_context(
                self._profile,
                executable_path=executable or chromium_path(),
                headless=True,
                args=list(CHROMIUM_ARGS),
                viewport={"width": viewport[0], "height": viewport[1]},
                timeout=timeout_s * 1000,
            )
        except Exception:
            self._pw.stop()
            shutil.rmtree(self._profile, ignore_errors=True)
            raise
        self.timeout_s = timeout_s
        self.console: list[str] = []

    def open(self, url: str, wait_ready: bool = True, setup: Any = None) -> AnnotationPage:
        """A new tab on `url`; `setup(page)` runs before it loads (e.g. playwright's route_web_socket)."""
        page = self.context.new_page()
        if setup is not None:
            setup(page)
        page.on("console", lambda m: self.console.append(f"{m.type}: {m.text}"))
        page.on("pageerror", lambda e: self.console.append(f"pageerror: {e}"))
        page.goto(url, wait_until="load", timeout=self.timeout_s * 1000)
        ap = AnnotationPage(page, self.timeout_s, self.console)
        if wait_ready:
            ap.wait_ready()
        return ap

    def close(self) -> None:
        try:
            self.context.close()
        finally:
            self._pw.stop()
            shutil.rmtree(self._profile, ignore_errors=True)

    def __enter__(self) -> HeadlessBrowser:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


class AnnotationPage:
    """The annotation page in a tab: read its state, mark a target, submit, screenshot."""

    def __init__(self, page: Any, timeout_s: float, console: list[str]):
        self.page = page
        self.timeout_s = timeout_s
        self.console = console

    # -- waiting -----------------------------------------------------------------------------------
    def wait_js(self, expression: str, arg: Any = None, timeout_s: float | None = None) -> Any:
        """Wait until a JS expression (a function of `arg`) is truthy; returns its value."""
        timeout = 1000 * (timeout_s or self.timeout_s)
        try:
            handle = self.page.wait_for_function(expression, arg=arg, timeout=timeout, polling=50)
        except Exception as exc:
            raise HeadlessError(
                f"page did not reach `{expression}` within {timeout / 1000:.0f} s; "
                f"state: {self._safe_state()}; console: {self.console[-8:]}"
            ) from exc
        return handle.json_value()

    def wait_ready(self) -> None:
        self.wait_js("() => window.mrguide && (window.mrguide.ready || window.mrguide.error)")
        err = self.page.evaluate("() => window.mrguide.error || null")
        if err:
            raise HeadlessError(f"the page failed to start: {err}; console: {self.console[-8:]}")

    def wait_request(self, request_id: str | None = None, timeout_s: float | None = None) -> dict[str, Any]:
        """Wait until the page shows a request (that one, if given) and has laid out its target."""
        self.wait_js(
            "(id) => { const s = window.mrguide.state(); return s.requestId && (!id || s.requestId === id) && s.target; }",
            request_id,
            timeout_s,
        )
        return self.state()

    def wait_robot(self, timeout_s: float | None = None) -> dict[str, Any]:
        """Wait until the arm's URDF and meshes have loaded (raises if they failed)."""
        self.wait_js("() => { const r = window.mrguide.state().robot; return r.loaded || r.error; }", None, timeout_s)
        robot = self.state()["robot"]
        if robot.get("error"):
            raise HeadlessError(f"robot model failed to load: {robot['error']}")
        return robot

    def wait_state(self, expression: str, timeout_s: float | None = None) -> dict[str, Any]:
        """Wait until `expression` (JS, a function of the state `s`) holds; returns the state."""
        self.wait_js(f"() => {{ const s = window.mrguide.state(); return ({expression}); }}", None, timeout_s)
        return self.state()

    def wait_drawn(self) -> None:
        """Ask the view (it draws on demand) for a frame and wait until it is drawn."""
        start = self.page.evaluate("() => { window.mrguide.redraw(); return window.mrguide.state().frames; }")
        self.wait_js("(f) => window.mrguide.state().frames > f", start)

    # -- reading and acting ------------------------------------------------------------------------
    def state(self) -> dict[str, Any]:
        return self.page.evaluate("() => window.mrguide.state()")

    def _safe_state(self) -> Any:
        try:
            return self.state()
        except Exception as exc:  # the page may be gone
            return f"<unavailable: {exc}>"

    def text(self, element_id: str) -> str:
        return self.page.inner_text(f"#{element_id}")

    def set_target(self, xyz: list[float]) -> list[float]:
        """Move the target through the test hook (what the gizmo does); returns the clamped, rounded target."""
        return self.page.evaluate("(p) => window.mrguide.setTarget(p)", [float(v) for v in xyz])

    def set_vacuum(self, on: bool) -> bool:
        return self.page.evaluate("(v) => window.mrguide.setVacuum(v)", bool(on))

    def submit(self) -> bool:
        """Submit through the test hook (no rendering or clicking in the way: for timing)."""
        return self.page.evaluate("() => window.mrguide.submit()")

    def auto_submit(self, on: bool = True) -> None:
        """Make the page answer each new request the moment it shows it (start target, suggested vacuum)."""
        self.page.evaluate("(on) => window.mrguide.autoSubmit(on)", bool(on))

    def skip(self) -> bool:
        return self.page.evaluate("() => window.mrguide.skip()")

    def click_submit(self) -> None:
        self.page.click("#submit", timeout=self.timeout_s * 1000)

    def click_skip(self) -> None:
        self.page.click("#skip", timeout=self.timeout_s * 1000)

    def press(self, key: str) -> None:
        self.page.keyboard.press(key)

    def gizmo_handle(self, axis: str = "X") -> dict[str, float]:
        handle = self.page.evaluate("(a) => window.mrguide.gizmoHandle(a)", axis)
        if not handle:
            raise HeadlessError(f"the gizmo's {axis} arrow is not under any pixel (hidden or edge-on?)")
        return handle

    def drag_gizmo(self, axis: str, dx: float, dy: float, steps: int = 6) -> list[float]:
        """Drag the gizmo's `axis` arrow by (dx, dy) screen pixels with the mouse; returns the new target."""
        h = self.gizmo_handle(axis)
        mouse = self.page.mouse
        mouse.move(h["x"], h["y"])
        mouse.down()
        mouse.move(h["x"] + dx / 2, h["y"] + dy / 2, steps=steps)
        mouse.move(h["x"] + dx, h["y"] + dy, steps=steps)
        mouse.up()
        return self.state()["target"]

    def mark_like_a_person(self, previous_id: str | None = None, timeout_s: float | None = None) -> dict[str, Any]:
        """Answer the next request with the mouse alone, as a person would: look at what it asks, click the
        part (a pick, or any phase up to the lift) or the goal (a place, transport), then click Submit. Returns
        {"id", "phase", "target", "actions" (clicks), "seconds" (from the request shown to the submit)}."""
        self.wait_js(
            "(id) => { const s = window.mrguide.state(); return s.requestId && s.requestId !== id && s.target; }",
            previous_id,
            timeout_s,
        )
        t0 = time.monotonic()
        req = self.page.evaluate("() => ({id: window.mrguide.state().requestId, phase: window.mrguide.state().phase})")
        shown = self.page.evaluate("() => window.mrguide.shown()")
        on_goal = shown["phase_index"] >= Phase.TRANSPORT
        spot = list(shown["goal"]) if on_goal else list(shown["object"])
        spot[2] = (
            0.001 if on_goal else spot[2] + 0.5 * shown["object_height"]
        )  # the goal ring on the table, the part's top
        px = self.page.evaluate("(p) => window.mrguide.screenOf(p)", spot)
        self.page.mouse.click(px["x"], px["y"])
        placed = self.wait_state(f"s.placedOn === '{'goal' if on_goal else 'object'}'")
        self.click_submit()
        self.wait_state(f"s.answers > {placed['answers']}")  # acked (the next request may already be shown)
        target = placed["target"]
        return {**req, "target": target, "actions": 2, "seconds": time.monotonic() - t0}

    def enter_xr(self) -> dict[str, Any]:
        """Click the headset button and wait until the session presents."""
        self.page.click("#xr-button", timeout=self.timeout_s * 1000)
        return self.wait_state("s.xr.presenting || s.xr.error")["xr"]

    def screenshot(self, path: str | Path) -> Path:
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        self.page.screenshot(path=str(path))
        return path

    def reload(self) -> None:
        self.page.reload(wait_until="load", timeout=self.timeout_s * 1000)
        self.wait_ready()

    def close(self) -> None:
        self.page.close()


def wait_until(predicate, timeout_s: float = 10.0, interval_s: float = 0.02) -> bool:
    """Poll a Python predicate (e.g. a broker counter) until it holds or the time is up."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if predicate():
            return True
        time.sleep(interval_s)
    return bool(predicate())
