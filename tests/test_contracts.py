"""Named contracts: the observation layout and the phases are named once (mrguide/task.py) and used by name.

The layout itself is pinned here with literal indices — the only place outside task.py that spells them out, as
exported policy files depend on it. Everywhere else in the package an observation is indexed by OBS_TCP, OBS_GRIP,
OBS_PROGRESS, OBS_OBJECT, OBS_GOAL and a phase compared with `Phase` members: the source is searched (by syntax
tree, so strings, comments and line breaks neither hide nor fake a hit) for

- a literal index or slice into an observation: a name `obs`, `observation(s)`, `*_obs` or `obs_*`, or a
  `["obs"]` entry, subscripted with an integer or a slice with integer bounds, or in a later axis (`obs[4]`,
  `obs[5:8]`, `o["obs"][:3]`, `obs[:, 4]`, `obs[..., 4:5]`);
- a phase compared with a bare number: a name, attribute, `["phase…"]` entry or call whose name holds "phase",
  compared with an integer or a tuple of them (`phase >= 2`, `2 <= phase`, `phase in (2, 3)`,
  `phase_from_progress(φ) == 4`, `req["phase_index"] >= 3`).

Tests are not searched: they may pin the task model with literal phases on purpose.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import numpy as np
import pytest

from mrguide import task
from mrguide.task import (
    ACT_DIM,
    ACT_LAYOUT,
    G_REQUIRED,
    N_PHASES,
    OBS_DIM,
    OBS_GOAL,
    OBS_GRIP,
    OBS_LAYOUT,
    OBS_OBJECT,
    OBS_PROGRESS,
    OBS_TCP,
    PHASES,
    PICK_PHASE,
    PLACE_PHASE,
    Phase,
    observation,
)

PACKAGE = Path(__file__).parents[1] / "mrguide"
OBS_NAME = re.compile(r"^(obs|observations?)$|^obs_|_obs$")
PHASE_NAME = re.compile(r"phase(?!s)", re.IGNORECASE)  # a phase, not the phases (N_PHASES, marks = "phases")


# -- the layout and the phases, pinned ------------------------------------------------------------------------------
def test_observation_layout_is_the_papers_state_plus_object_and_goal():
    assert OBS_LAYOUT == (
        "tcp_x",
        "tcp_y",
        "tcp_z",
        "g",
        "phi",
        "obj_x",
        "obj_y",
        "obj_z",
        "goal_x",
        "goal_y",
        "goal_z",
    )
    assert OBS_DIM == 11 and ACT_DIM == len(ACT_LAYOUT) == 4
    assert (slice(0, 3), 3, 4, slice(5, 8), slice(8, 11)) == (OBS_TCP, OBS_GRIP, OBS_PROGRESS, OBS_OBJECT, OBS_GOAL)
    names = np.array(OBS_LAYOUT)
    assert list(names[OBS_TCP]) == ["tcp_x", "tcp_y", "tcp_z"] and names[OBS_GRIP] == "g"
    assert names[OBS_PROGRESS] == "phi" and list(names[OBS_OBJECT]) == ["obj_x", "obj_y", "obj_z"]
    assert list(names[OBS_GOAL]) == ["goal_x", "goal_y", "goal_z"]


def test_the_parts_cover_the_observation_once():
    covered = sorted(
        [i for part in (OBS_TCP, OBS_OBJECT, OBS_GOAL) for i in range(OBS_DIM)[part]] + [OBS_GRIP, OBS_PROGRESS]
    )
    assert covered == list(range(OBS_DIM))


def test_observation_puts_each_part_where_the_layout_says():
    tcp, obj, goal = np.array([0.1, 0.2, 0.3]), np.array([0.4, 0.5, 0.6]), np.array([0.7, 0.8, 0.9])
    obs = observation(tcp, -1, 0.6, obj, goal)
    assert obs.shape == (OBS_DIM,) and obs.dtype == np.float32
    assert np.allclose(obs[OBS_TCP], tcp) and obs[OBS_GRIP] == -1.0 and obs[OBS_PROGRESS] == pytest.approx(0.6)
    assert np.allclose(obs[OBS_OBJECT], obj) and np.allclose(obs[OBS_GOAL], goal)


def test_phases_are_the_papers_five_in_order():
    assert [p.value for p in Phase] == list(range(N_PHASES)) == [0, 1, 2, 3, 4]
    assert PHASES == ("approach", "grasp", "lift", "transport", "release")
    assert [p.name.lower() for p in Phase] == list(PHASES) and len(G_REQUIRED) == N_PHASES
    assert (PICK_PHASE, PLACE_PHASE) == (Phase.GRASP, Phase.RELEASE)
    assert task.phase_from_progress(task.progress(Phase.TRANSPORT)) == Phase.TRANSPORT == 3


def test_a_phase_is_an_int_on_the_wire():
    import json

    assert json.dumps({"phase": Phase.LIFT}) == '{"phase": 2}' and f"{Phase.LIFT}" == str(Phase.LIFT) == "2"
    assert PHASES[Phase.RELEASE] == "release" and G_REQUIRED[Phase.GRASP] == 1


# -- the source search ----------------------------------------------------------------------------------------------
def _int(node: ast.AST) -> bool:
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, ast.USub):
        node = node.operand
    return isinstance(node, ast.Constant) and type(node.value) is int


def _literal_position(node: ast.AST) -> bool:
    """An integer, or a slice with an integer bound."""
    if isinstance(node, ast.Slice):
        return any(b is not None and _int(b) for b in (node.lower, node.upper))
    return _int(node)


def _is_observation(node: ast.AST) -> bool:
    if isinstance(node, ast.Name):
        return bool(OBS_NAME.search(node.id))
    return (
        isinstance(node, ast.Subscript)
        and isinstance(node.slice, ast.Constant)
        and node.slice.value in ("obs", "observation")
    )


def magic_observation_indices(tree: ast.AST) -> list[ast.Subscript]:
    hits = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Subscript) or not _is_observation(node.value):
            continue
        index = node.slice
        if isinstance(index, ast.Tuple):  # a batch: the first axis is the rows, any later one the observation
            if any(_literal_position(e) for e in index.elts[1:]):
                hits.append(node)
        elif _literal_position(index):
            hits.append(node)
    return hits


def _names_phase(node: ast.AST) -> bool:
    if isinstance(node, ast.Call):
        return _names_phase(node.func)
    if isinstance(node, ast.Name):
        return bool(PHASE_NAME.search(node.id))
    if isinstance(node, ast.Attribute):
        return bool(PHASE_NAME.search(node.attr))
    if isinstance(node, ast.Subscript) and isinstance(node.slice, ast.Constant):
        return isinstance(node.slice.value, str) and bool(PHASE_NAME.search(node.slice.value))
    return False


def _bare_numbers(node: ast.AST) -> bool:
    if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
        return any(_int(e) for e in node.elts)
    return _int(node)


def bare_phase_comparisons(tree: ast.AST) -> list[ast.Compare]:
    hits = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Compare):
            operands = [node.left, *node.comparators]
            if any(_names_phase(o) for o in operands) and any(_bare_numbers(o) for o in operands):
                hits.append(node)
    return hits


def _offences(find) -> list[str]:
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        tree = ast.parse(path.read_text(), str(path))
        found += [f"{path.relative_to(PACKAGE.parent)}:{n.lineno}: {ast.unparse(n)}" for n in find(tree)]
    return found


def test_no_literal_index_into_an_observation_in_the_package():
    assert _offences(magic_observation_indices) == [], "index observations by task.OBS_* names"


def test_no_phase_compared_with_a_bare_number_in_the_package():
    assert _offences(bare_phase_comparisons) == [], "compare phases with task.Phase members"


#: What the search must catch (the forms replaced when the names were introduced) and must let pass.
CAUGHT_INDICES = (
    "phase_from_progress(obs[4])",
    "phase_target(phase, obs[5:8], obs[8:11], cfg)",
    "np.linalg.norm(obs[0:3] - target)",
    "bad_obs[:3]",
    "asking_obs[4] = 0.2",
    'steps[0]["obs"][5:8]',
    "next_obs[..., 4:5] > 0.5",
    "obs[:, OBS_PROGRESS : OBS_PROGRESS + 1] + obs[:, 5:8]",
    "observation[-1]",
)
PASSED_INDICES = (
    "obs[OBS_PROGRESS]",
    "obs[..., OBS_PROGRESS : OBS_PROGRESS + 1]",
    "obs[:, OBS_GOAL]",
    "obs[bad[0]]",
    "obs[None]",
    "self.replay.agent.obs[:5]",  # rows of a buffer
    "actions[:, :3]",
    "points[idx[:, k]]",
)
CAUGHT_PHASES = (
    "phase >= 2",
    "self.decision.phase == 4",
    "2 <= phase",
    "phase in (2, 3)",
    "next_phase <= 1",
    "phase_from_progress(obs[OBS_PROGRESS]) == 4",
    'shown["phase_index"] >= 3',
)
PASSED_PHASES = (
    "phase >= Phase.LIFT",
    "phase in (Phase.LIFT, Phase.TRANSPORT)",
    "kind == PICK_PHASE",
    "len(PHASES) == 5",
    "N_PHASES == 5",  # a count, not a phase
    "phase < N_PHASES",
    "self.phase is None",
)


@pytest.mark.parametrize("code", CAUGHT_INDICES)
def test_the_index_search_catches(code):
    assert magic_observation_indices(ast.parse(code))


@pytest.mark.parametrize("code", PASSED_INDICES)
def test_the_index_search_lets_pass(code):
    assert not magic_observation_indices(ast.parse(code))


@pytest.mark.parametrize("code", CAUGHT_PHASES)
def test_the_phase_search_catches(code):
    assert bare_phase_comparisons(ast.parse(code))


@pytest.mark.parametrize("code", PASSED_PHASES)
def test_the_phase_search_lets_pass(code):
    assert not bare_phase_comparisons(ast.parse(code))


# -- the names a config chooses between -----------------------------------------------------------------------------
def test_every_name_has_its_entry_in_the_registry():
    from mrguide.policies.choices import EXPERT_SOURCES, REFERENCES
    from mrguide.policies.guidance import REFERENCE_POSES
    from mrguide.policies.guided_expert import IN_PROCESS_SOURCES

    assert list(IN_PROCESS_SOURCES) + ["live"] == list(EXPERT_SOURCES)  # a person is attached by the CLI
    assert list(REFERENCE_POSES) == list(REFERENCES)


@pytest.mark.parametrize(
    "section, key, value, message",
    [
        (
            "guidance",
            "source",
            "oracel",
            "guidance.source must be 'oracle', 'annotator', 'file' or 'live', got 'oracel'",
        ),
        ("guidance", "marks", "sideways", "guidance.marks must be 'phases' or 'pick_place', got 'sideways'"),
        ("guidance", "reference", "mean", "guidance.reference must be 'nominal' or 'running_median', got 'mean'"),
        ("guidance", "marks", 3, "guidance.marks must be 'phases' or 'pick_place', got 3"),
        ("peers", "learners", ["sac", "td3"], "experiment.learners = ['sac', 'td3']: expected some of ddpg, sac"),
    ],
)
def test_a_value_outside_its_choices_gets_the_keys_own_message(section, key, value, message):
    """Loaded through dacite, a `Literal` field's bad value is refused by the config's own check, not by dacite's
    type check (which would name only the type)."""
    from mrguide.config import ConfigError, from_dict
    from mrguide.experiments.peers import PeersConfig
    from mrguide.policies.guidance import GuidanceConfig

    cls = {"guidance": GuidanceConfig, "peers": PeersConfig}[section]
    with pytest.raises(ConfigError) as err:
        from_dict(cls, {key: value}, "run.toml [x]")
    assert str(err.value) == f"run.toml [x]: {message}"


def test_a_learner_nobody_registered_is_refused_naming_the_file(tmp_path):
    """`train.learner` is checked against the learner registry by the run's root config, where the file is known."""
    from mrguide.config import ConfigError
    from mrguide.policies.train_config import RunConfig

    path = tmp_path / "run.toml"
    path.write_text("[train]\nlearner = 'td3'\n")
    with pytest.raises(ConfigError) as err:
        RunConfig.load(path)
    assert str(err.value) == f"{path} [train]: train.learner = 'td3': expected one of ddpg, sac"


def test_the_choices_load():
    from mrguide.config import from_dict
    from mrguide.experiments.peers import PeersConfig
    from mrguide.policies.guidance import GuidanceConfig

    g = from_dict(GuidanceConfig, {"source": "oracle", "marks": "phases", "reference": "running_median"})
    assert (g.source, g.marks, g.reference) == ("oracle", "phases", "running_median")
    assert from_dict(PeersConfig, {"learners": ["sac"]}).learners == ("sac",)


# -- outcomes -------------------------------------------------------------------------------------------------------
def test_an_outcome_is_written_as_its_value():
    import csv
    import io
    import json

    from mrguide.task import Outcome

    buf = io.StringIO()
    csv.writer(buf).writerow([Outcome.SAFETY_STOP])
    assert buf.getvalue().strip() == "safety_stop" == Outcome.SAFETY_STOP.value
    assert json.dumps({"outcome": Outcome.POSE_LOST}) == '{"outcome": "pose_lost"}'
    assert Outcome("no_grasp") is Outcome.NO_GRASP and Outcome.NO_GRASP == "no_grasp"


def test_a_deploy_summary_counts_outcomes_by_value():
    from mrguide.deploy.episode import EpisodeReport
    from mrguide.deploy.session import DeploySummary
    from mrguide.task import Outcome

    summary = DeploySummary([EpisodeReport(0, Outcome.SUCCESS, 5, {}), EpisodeReport(1, Outcome.DROPPED, 3, {})])
    assert summary.successes == 1 and summary.outcomes() == {"success": 1, "dropped": 1}
    assert "outcomes: {'success': 1, 'dropped': 1}" in summary.text()
