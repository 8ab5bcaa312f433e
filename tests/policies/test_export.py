"""Export to the numpy policy file; the deploy loader matches torch and refuses bad files."""

import dataclasses
import json

import numpy as np
import pytest
import torch

from mrguide.deploy.policy import ExportedPolicy, PolicyFileError
from mrguide.policies.ddpg import DDPG, DDPGConfig
from mrguide.policies.export import export_actor
from mrguide.policies.networks import obs_scaling
from mrguide.robot import RobotConfig, Workspace, load_robot
from mrguide.task import TaskConfig


@pytest.fixture()
def exported(tmp_path):
    spec = load_robot()
    ws = spec.workspace
    agent = DDPG(*obs_scaling(ws), 4, DDPGConfig(), seed=3)
    path = export_actor(agent.actor, tmp_path / "policy.npz", spec, TaskConfig(), 0.1, {"trained": {"steps": 0}})
    return agent, path, ws


def test_numpy_matches_torch(exported):
    agent, path, ws = exported
    pol = ExportedPolicy.load(path, load_robot(), TaskConfig())
    rng = np.random.default_rng(0)
    obs = np.concatenate(
        [
            rng.uniform(ws.lo, ws.hi, (500, 3)),
            rng.choice([-1, 1], (500, 1)),
            rng.uniform(0, 1, (500, 1)),
            rng.uniform(ws.lo, ws.hi, (500, 3)),
            rng.uniform(ws.lo, ws.hi, (500, 3)),
        ],
        axis=1,
    ).astype(np.float32)
    with torch.no_grad():
        ref = agent.actor(torch.as_tensor(obs)).numpy()
    got = np.array([pol(o) for o in obs])
    assert np.max(np.abs(got - ref)) < 1e-5


def _rewrite(path, out, mutate):
    with np.load(path) as npz:
        arrays = {k: npz[k] for k in npz.files}
    mutate(arrays)
    np.savez(out, **arrays)
    return out


def test_wrong_shapes_refused(exported, tmp_path):
    _, path, _ws = exported
    bad = _rewrite(path, tmp_path / "bad.npz", lambda a: a.update(W0=np.zeros((256, 12), np.float32)))
    with pytest.raises(PolicyFileError, match="layer 0 has weights"):
        ExportedPolicy.load(bad)
    bad = _rewrite(path, tmp_path / "nan.npz", lambda a: a["b1"].__setitem__(0, np.nan))
    with pytest.raises(PolicyFileError, match="NaN"):
        ExportedPolicy.load(bad)


def test_wrong_metadata_refused(exported, tmp_path):
    _, path, _ws = exported

    def meta(change):
        def mutate(a):
            m = json.loads(str(a["metadata"]))
            change(m)
            a["metadata"] = np.array(json.dumps(m))

        return mutate

    bad = _rewrite(path, tmp_path / "layout.npz", meta(lambda m: m.update(obs_layout=["x"] * 11)))
    with pytest.raises(PolicyFileError, match="layout"):
        ExportedPolicy.load(bad)
    bad = _rewrite(path, tmp_path / "fmt.npz", meta(lambda m: m.update(format_version=99)))
    with pytest.raises(PolicyFileError, match="format"):
        ExportedPolicy.load(bad)
    with pytest.raises(PolicyFileError, match="workspace"):
        ExportedPolicy.load(
            path, load_robot(RobotConfig(workspace=Workspace(low=(0.3, -0.2, 0.1), high=(0.65, 0.4, 0.35))))
        )
    with pytest.raises(PolicyFileError, match="epsilon"):
        ExportedPolicy.load(path, load_robot(), TaskConfig(epsilon=0.03))


def test_unreadable_file_refused(tmp_path):
    p = tmp_path / "junk.npz"
    p.write_bytes(b"not a zip")
    with pytest.raises(PolicyFileError, match="not a readable policy file"):
        ExportedPolicy.load(p)
    with pytest.raises(PolicyFileError, match="not found"):
        ExportedPolicy.load(tmp_path / "missing.npz")


def _random_obs(ws: Workspace, n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.concatenate(
        [
            rng.uniform(ws.lo, ws.hi, (n, 3)),
            rng.choice([-1, 1], (n, 1)),
            rng.uniform(0, 1, (n, 1)),
            rng.uniform(ws.lo, ws.hi, (n, 3)),
            rng.uniform(ws.lo, ws.hi, (n, 3)),
        ],
        axis=1,
    ).astype(np.float32)


def _policy(tmp_path):
    spec = load_robot()
    agent = DDPG(*obs_scaling(spec.workspace), 4, DDPGConfig(), seed=4)
    with torch.no_grad():  # weights large enough that some targets leave the box and are clipped
        for p in agent.actor.net.parameters():
            p.mul_(3.0)
    return agent, export_actor(agent.actor, tmp_path / "policy.npz", spec, TaskConfig(), 0.1)


def test_the_anchored_head_exports_and_runs_the_same_in_numpy_in_every_phase(tmp_path):
    agent, path = _policy(tmp_path)
    pol = ExportedPolicy.load(path, load_robot(), TaskConfig())
    assert pol.metadata["head"] == {"kind": "anchor_offset", "max_offset": 0.5, "carry_progress": 0.5}
    obs = _random_obs(load_robot().workspace, 500)
    obs[:, 4] = np.random.default_rng(1).choice([0.0, 0.2, 0.4, 0.6, 0.8, 1.0], 500)  # every phase, both layers
    with torch.no_grad():
        ref = agent.actor(torch.as_tensor(obs)).numpy()
    got = pol.batch(obs)
    assert np.max(np.abs(got - ref)) < 1e-5 and np.any(np.abs(got[:, :3]) == 1.0) and np.any(np.abs(got[:, :3]) < 0.9)


def test_the_policy_follows_the_object_before_transport_and_the_goal_from_it():
    """Before transport the target moves with TCP + object and ignores the goal; from transport on it moves
    with TCP + goal and ignores the object."""
    ws = Workspace(low=(-1.0, -1.0, 0.045), high=(2.0, 2.0, 0.35))  # large enough that nothing is clipped
    agent = DDPG(*obs_scaling(ws), 4, DDPGConfig(), seed=1)
    obs = _random_obs(load_robot().workspace, 200)

    def target(o):
        with torch.no_grad():
            return ws.to_cartesian(agent.actor(torch.as_tensor(o)).numpy()[:, :3])

    for phi, anchor, other in ((0.2, 5, 8), (0.6, 8, 5)):
        obs[:, 4] = phi
        moved, unrelated = obs.copy(), obs.copy()
        for k in (0, anchor):
            moved[:, k] += 0.4
            moved[:, k + 1] -= 0.3
        unrelated[:, other : other + 2] += 0.25
        assert np.allclose(target(moved) - target(obs), [0.4, -0.3, 0.0], atol=1e-5)
        assert np.allclose(target(unrelated), target(obs), atol=1e-6)


def test_the_offset_is_added_to_the_object_before_transport_and_to_the_goal_from_it(tmp_path):
    """With a constant MLP output the target is anchor + MAX_OFFSET · tanh(bias), the object (before transport) or
    the goal (from transport on); torch and the numpy runner alike."""
    ws = Workspace(low=(-1.0, -1.0, -1.0), high=(2.0, 2.0, 2.0))  # large enough that nothing is clipped
    agent = DDPG(*obs_scaling(ws), 4, DDPGConfig(), seed=2)
    last = agent.actor.net[-2]
    with torch.no_grad():
        last.weight.zero_()
        last.bias.copy_(torch.tensor([0.1, -0.2, 0.3, 0.5]))
    spec = dataclasses.replace(load_robot(), workspace=ws)  # a file for the large box; loaded without an arm
    pol = ExportedPolicy.load(export_actor(agent.actor, tmp_path / "policy.npz", spec, TaskConfig(), 0.1))
    obs = _random_obs(load_robot().workspace, 300)
    obs[:, 4] = np.random.default_rng(3).choice([0.0, 0.2, 0.4, 0.6, 0.8, 1.0], 300)
    before = obs[:, 4] <= 0.5
    expected = np.where(before[:, None], obs[:, 5:8], obs[:, 8:11]) + 0.5 * np.tanh([0.1, -0.2, 0.3])
    with torch.no_grad():
        from_torch = ws.to_cartesian(agent.actor(torch.as_tensor(obs)).numpy()[:, :3])
    assert np.allclose(from_torch, expected, atol=1e-5)
    assert np.allclose(ws.to_cartesian(pol.batch(obs)[:, :3]), expected, atol=1e-5)


def test_a_file_without_its_carry_layer_refused(tmp_path):
    _, path = _policy(tmp_path)
    bad = _rewrite(path, tmp_path / "bad.npz", lambda a: a.pop("W0_carry"))
    with pytest.raises(PolicyFileError, match="W0_carry"):
        ExportedPolicy.load(bad)
    bad = _rewrite(path, tmp_path / "short.npz", lambda a: a.update(b0_carry=np.zeros(3)))
    with pytest.raises(PolicyFileError, match="carry layer"):
        ExportedPolicy.load(bad)


def _with_head(head):
    def mutate(arrays):
        meta = json.loads(str(arrays["metadata"]))
        if head is None:
            meta.pop("head")
        else:
            meta["head"] = head
        arrays["metadata"] = np.array(json.dumps(meta))

    return mutate


@pytest.mark.parametrize(
    "head",
    [
        {"kind": "anchor_offset", "max_offset": "far", "carry_progress": 0.5},
        {"kind": "anchor_offset", "max_offset": 0.5, "carry_progress": 1.5},
        {"kind": "sideways"},
        [],
    ],
)
def test_a_head_not_understood_is_refused(exported, tmp_path, head):
    _, path, _ = exported
    with pytest.raises(PolicyFileError, match=r"head .* not understood"):
        ExportedPolicy.load(_rewrite(path, tmp_path / "bad.npz", _with_head(head)), load_robot(), TaskConfig())


@pytest.mark.parametrize("head", [{"kind": "absolute"}, {"kind": "tcp_offset", "max_offset": 0.5}, None])
def test_a_file_of_a_retired_head_is_refused_with_the_reason(exported, tmp_path, head):
    """Files of earlier versions (absolute targets, also files without the field; tcp_offset; phase_anchor)."""
    _, path, _ = exported
    with pytest.raises(
        PolicyFileError, match=r"no longer runs \(retired in mrguide 0.2.0\); train and export the policy again"
    ):
        ExportedPolicy.load(_rewrite(path, tmp_path / "old.npz", _with_head(head)), load_robot(), TaskConfig())
