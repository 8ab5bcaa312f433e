"""Screenshot a Rerun recording in Rerun's web viewer, in headless Chromium under SwiftShader (WebGL).

    python -m mrguide.replay.screenshot RECORDING.rrd OUT.png [--wait S] [--width W] [--height H]

Starts `rerun RECORDING --web-viewer` on loopback ports, opens the page with Debian's chromium through the
`playwright` package (mrguide.annotation.headless's browser flags), waits, and saves a full-page PNG. What it
shows is whatever the viewer drew in that time: look at the PNG before trusting it.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

from playwright.sync_api import sync_playwright

from mrguide.annotation.headless import CHROMIUM_ARGS, chromium_path


def main() -> int:
    p = argparse.ArgumentParser()
    p.add_argument("recording")
    p.add_argument("out")
    p.add_argument("--wait", type=float, default=25.0, help="seconds to let the viewer load and draw")
    p.add_argument("--width", type=int, default=1600)
    p.add_argument("--height", type=int, default=900)
    p.add_argument("--web-port", type=int, default=9190)
    p.add_argument("--grpc-port", type=int, default=9977)
    args = p.parse_args()
    viewer = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "rerun",
            args.recording,
            "--web-viewer",
            "--bind",
            "127.0.0.1",
            "--web-viewer-port",
            str(args.web_port),
            "--port",
            str(args.grpc_port),
            "--renderer",
            "webgl",
        ],
        env={"BROWSER": "true", "PATH": "/usr/bin:/bin", "HOME": str(Path.home())},
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,  # `python -m rerun` runs the viewer binary as a child: end the whole group
    )
    try:
        time.sleep(3.0)
        url = (
            f"http://127.0.0.1:{args.web_port}/?url=rerun%2Bhttp%3A%2F%2F127.0.0.1%3A{args.grpc_port}%2Fproxy"
            "&renderer=webgl"
        )
        with sync_playwright() as pw:
            browser = pw.chromium.launch(executable_path=chromium_path(), args=list(CHROMIUM_ARGS), headless=True)
            page = browser.new_page(viewport={"width": args.width, "height": args.height})
            page.goto(url)
            time.sleep(args.wait)
            page.screenshot(path=args.out)
            browser.close()
    finally:
        os.killpg(viewer.pid, signal.SIGTERM)
        viewer.wait(timeout=10)
    print(args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
