"""A person's run sees the part as the cell does by default: `--expert live` perceives it through the HMD
pipeline's errors (`LIVE_POSE`) unless [guidance.pose] says otherwise, the source is shown the part where the cell
sees it (the page draws and snaps to it there), the record keeps the observation, and run.json names the source
that ran."""

import dataclasses

import numpy as np

from mrguide.experiments.train_runs import TrainRun, run_config, run_record
from mrguide.policies.annotations import Annotation, AnnotationCache
from mrguide.policies.guidance import LIVE_POSE, NominalReference, PoseError
from mrguide.policies.guided_expert import GuidedExpert
from mrguide.policies.train_config import RunConfig
from mrguide.robot import load_robot
from mrguide.task import OBS_OBJECT, TaskConfig, oracle_target
from tests.policies.mark_scene import OBJ, scene_obs


def test_a_live_run_perceives_the_part_through_the_hmd_errors_unless_the_config_says_otherwise(tmp_path):
    default = RunConfig.load(None)
    assert default.guidance.pose_error == PoseError()  # the simulated annotator: the part as observed
    live = default.guidance.__class__(source="live")
    assert live.pose_error == LIVE_POSE and LIVE_POSE.sigma > 0 and LIVE_POSE.bias_sigma > 0
    exact = tmp_path / "exact.toml"
    exact.write_text("[guidance.pose]\nsigma = 0.0\nbias_sigma = 0.0\n")
    said = RunConfig.load(exact).with_overrides({"guidance.source": "live"})
    assert said.guidance.pose_error == PoseError()  # the config's word stands
    assert default.with_overrides({"guidance.pose.sigma": 0.002}).guidance.pose == PoseError(sigma=0.002)


class _Shown:
    """An expert source that records the observation it is shown and answers at its part's top."""

    def __init__(self):
        self.shown = []

    def annotate(self, obs, previous=None):
        self.shown.append(np.array(obs))
        target, grip = oracle_target(obs, TaskConfig())
        return Annotation(target, grip, "live")


def _ask_once(tmp_path, pose_error):
    src, task = _Shown(), TaskConfig()
    cache = AnnotationCache(0.005, tmp_path / f"ann-{pose_error.sigma}.jsonl")
    expert = GuidedExpert(
        src, NominalReference(task), cache, 0.05, task, load_robot().workspace.to_normalized, pose_error=pose_error
    )
    expert.begin_demonstration()
    expert.action(scene_obs(1))
    return src.shown[0], next(iter(cache.history()))[0]


def test_the_source_is_shown_the_part_where_the_cell_sees_it_and_the_record_keeps_the_observation(tmp_path):
    shown, recorded = _ask_once(tmp_path, LIVE_POSE)
    seen_error = np.linalg.norm(shown[OBS_OBJECT] - np.asarray(OBJ))
    assert 0.0 < seen_error < 0.03  # a few mm off, where the cell's pose pipeline puts it
    assert np.allclose(recorded[OBS_OBJECT], OBJ)  # the annotation is recorded with the observation
    shown, _ = _ask_once(tmp_path, PoseError())
    assert np.array_equal(shown, scene_obs(1))  # exact: the observation itself, untouched


def test_a_bot_run_over_the_wire_trains_and_records_the_live_source():
    run = TrainRun(name="bot-seed0", seed=0, steps=100, guided=True, client="bot")
    assert run_config(run).guidance.source == "live"
    assert run_record(run)["effective_config"]["guidance"]["source"] == "live"
    in_process = dataclasses.replace(run, client="")
    assert run_config(in_process).guidance.source == "annotator"
