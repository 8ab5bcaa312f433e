"""A person at the page, with the mouse alone, guiding a short training run over the live protocol: each mark
is one click on what the request asks about and one on Submit, and the trainer gets exactly those marks."""

from __future__ import annotations

import dataclasses
import json
import statistics
import threading

import numpy as np
import pytest

from mrguide.annotation.live import LiveOptions, LiveSession
from mrguide.policies.train import Trainer
from tests.run_configs import run_config, sections


def test_a_person_guides_a_short_run_with_two_clicks_per_mark(browser, tmp_path):
    tc, dc, gc, ec = sections()
    tc = dataclasses.replace(
        tc, total_steps=160, learning_starts=64, batch_size=32, eval_every=10_000, checkpoint_every=10_000
    )
    gc = dataclasses.replace(gc, intake_steps=160)
    session = LiveSession(LiveOptions(port=0))
    trainer = Trainer(
        run_config(tc, dataclasses.replace(dc, hidden=(16, 16)), gc, ec), tmp_path, session.source_factory
    )
    done = threading.Event()

    def train() -> None:
        try:
            trainer.run()
        finally:
            done.set()

    thread = threading.Thread(target=train, daemon=True)
    thread.start()
    marks, last = [], None
    page = browser.open(session.url)
    try:
        page.wait_robot()
        while not done.is_set() and len(marks) < 6:
            try:
                mark = page.mark_like_a_person(last, timeout_s=20)
            except Exception:
                if done.is_set():
                    break
                raise
            marks.append(mark)
            last = mark["id"]
    finally:
        page.close()
        session.interrupt()
        thread.join(60)
        trainer.close()
        session.close()
    assert len(marks) >= 2 and {m["phase"] for m in marks} <= {"grasp", "release"}  # pick and place marks only
    assert statistics.median(m["actions"] for m in marks) <= 2
    records = [json.loads(line) for line in (tmp_path / "annotations.jsonl").read_text().splitlines()]
    by_request = {r["request"]: r for r in records}
    for m in marks:  # what the person clicked is what the trainer recorded: the part's top centre or the goal
        rec = by_request[m["id"]]
        obs = np.array(rec["obs"])
        anchor = obs[5:8] if m["phase"] == "grasp" else obs[8:11]
        assert rec["client"] == "browser" and np.allclose(rec["target"], m["target"], atol=1e-9)
        assert np.allclose(rec["target"][:2], anchor[:2], atol=1e-4) and rec["target"][2] == pytest.approx(
            ec.task.object_height
        )
