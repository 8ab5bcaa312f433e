"""Export to the numpy policy file; the deploy loader matches torch and refuses bad files."""

import dataclasses
import json

import numpy as np
import pytest
import torch

from mrguide.deploy.policy import ExportedPolicy, PolicyFileError
from mrguide.policies.ddpg import DDPG, DDPGConfig
from mrguide.policies.export import export_actor
from mrguide.policies.ddpg import obs_scaling
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
    obs = np.concatenate([rng.uniform(ws.lo, ws.hi, (500, 3)), rng.choice([-1, 1], (500, 1)), rng.uniform(0, 1, (500, 1)),
                          rng.uniform(ws.lo, ws.hi, (500, 3)), rng.uniform(ws.lo, ws.hi, (500, 3))], axis=1).astype(np.float32)
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
    _, path, ws = exported
    bad = _rewrite(path, tmp_path / "bad.npz", lambda a: a.update(W0=np.zeros((256, 12), np.float32)))
    with pytest.raises(PolicyFileError, match="layer 0 has weights"):
        ExportedPolicy.load(bad)
    bad = _rewrite(path, tmp_path / "nan.npz", lambda a: a["b1"].__setitem__(0, np.nan))
    with pytest.raises(PolicyFileError, match="NaN"):
        ExportedPolicy.load(bad)


def test_wrong_metadata_refused(exported, tmp_path):
    _, path, ws = exported

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
        ExportedPolicy.load(path, load_robot(RobotConfig(workspace=Workspace(low=(0.3, -0.2, 0.1), high=(0.65, 0.4, 0.35)))))
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
    return np.concatenate([rng.uniform(ws.lo, ws.hi, (n, 3)), rng.choice([-1, 1], (n, 1)), rng.uniform(0, 1, (n, 1)),
                           rng.uniform(ws.lo, ws.hi, (n, 3)), rng.uniform(ws.lo, ws.hi, (n, 3))], axis=1).astype(np.float32)


def test_tcp_offset_head_exports_and_runs_the_same_in_numpy(tmp_path):
    spec = load_robot()
    ws = spec.workspace
    agent = DDPG(*obs_scaling(ws), 4, DDPGConfig(actor_head="tcp_offset", max_offset=0.3), seed=3)
    with torch.no_grad():  # weights large enough that some targets leave the box and are clipped
        for p in agent.actor.net.parameters():
            p.mul_(3.0)
    path = export_actor(agent.actor, tmp_path / "policy.npz", spec, TaskConfig(), 0.1)
    pol = ExportedPolicy.load(path, spec, TaskConfig())
    assert pol.metadata["head"] == {"kind": "tcp_offset", "max_offset": 0.3}
    obs = _random_obs(ws, 500)
    with torch.no_grad():
        ref = agent.actor(torch.as_tensor(obs)).numpy()
    got = pol.batch(obs)
    assert np.max(np.abs(got - ref)) < 1e-5 and np.any(np.abs(got[:, :3]) == 1.0) and np.any(np.abs(got[:, :3]) < 0.9)


def test_tcp_offset_policy_moves_with_the_scene_in_x_and_y():
    """Shift TCP, object and goal together: the target shifts with them; the absolute head does not."""
    ws = Workspace(low=(-1.0, -1.0, 0.045), high=(2.0, 2.0, 0.35))  # large enough that nothing is clipped
    obs = _random_obs(load_robot().workspace, 200)
    shifted = obs.copy()
    for k in (0, 5, 8):
        shifted[:, k] += 0.4
        shifted[:, k + 1] -= 0.3
    moved = {}
    for head in ("tcp_offset", "absolute"):
        agent = DDPG(*obs_scaling(ws), 4, DDPGConfig(actor_head=head, max_offset=0.3), seed=1)
        with torch.no_grad():
            a, b = (ws.to_cartesian(agent.actor(torch.as_tensor(o)).numpy()[:, :3]) for o in (obs, shifted))
        moved[head] = b - a
    assert np.allclose(moved["tcp_offset"], [0.4, -0.3, 0.0], atol=1e-5)
    assert not np.allclose(moved["absolute"], [0.4, -0.3, 0.0], atol=1e-2)


def test_unknown_head_refused(exported, tmp_path):
    _, path, _ = exported

    def head(arrays):
        meta = json.loads(str(arrays["metadata"]))
        meta["head"] = {"kind": "tcp_offset", "max_offset": "far"}
        arrays["metadata"] = np.array(json.dumps(meta))

    with pytest.raises(PolicyFileError, match="head"):
        ExportedPolicy.load(_rewrite(path, tmp_path / "bad.npz", head), load_robot(), TaskConfig())


ANCHOR_HEADS = ("phase_anchor", "anchor_offset")


def _anchor_policy(tmp_path, head):
    spec = load_robot()
    agent = DDPG(*obs_scaling(spec.workspace), 4, DDPGConfig(actor_head=head, max_offset=0.3), seed=4)
    with torch.no_grad():  # weights large enough that some targets leave the box and are clipped
        for p in agent.actor.net.parameters():
            p.mul_(3.0)
    return agent, export_actor(agent.actor, tmp_path / "policy.npz", spec, TaskConfig(), 0.1)


@pytest.mark.parametrize("head", ANCHOR_HEADS)
def test_anchor_heads_export_and_run_the_same_in_numpy(tmp_path, head):
    agent, path = _anchor_policy(tmp_path, head)
    pol = ExportedPolicy.load(path, load_robot(), TaskConfig())
    assert pol.metadata["head"] == {"kind": head, "max_offset": 0.3, "carry_progress": 0.5}
    obs = _random_obs(load_robot().workspace, 500)
    obs[:, 4] = np.random.default_rng(1).choice([0.0, 0.2, 0.4, 0.6, 0.8, 1.0], 500)  # every phase, both layers
    with torch.no_grad():
        ref = agent.actor(torch.as_tensor(obs)).numpy()
    got = pol.batch(obs)
    assert np.max(np.abs(got - ref)) < 1e-5 and np.any(np.abs(got[:, :3]) == 1.0) and np.any(np.abs(got[:, :3]) < 0.9)


@pytest.mark.parametrize("head", ANCHOR_HEADS)
def test_anchor_policies_follow_the_object_before_transport_and_the_goal_from_it(head):
    """Before transport the target moves with TCP + object and ignores the goal; from transport on it moves
    with TCP + goal and ignores the object."""
    ws = Workspace(low=(-1.0, -1.0, 0.045), high=(2.0, 2.0, 0.35))  # large enough that nothing is clipped
    agent = DDPG(*obs_scaling(ws), 4, DDPGConfig(actor_head=head, max_offset=0.3), seed=1)
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


@pytest.mark.parametrize("head, base", [("phase_anchor", (0, 0)), ("anchor_offset", (5, 8))])
def test_anchor_offset_adds_its_offset_to_the_anchor_and_phase_anchor_to_the_tcp(tmp_path, head, base):
    """With a constant MLP output the target is base + max_offset · tanh(bias): the TCP for phase_anchor, the
    object (before transport) or the goal (from transport on) for anchor_offset; torch and the numpy runner alike."""
    ws = Workspace(low=(-1.0, -1.0, -1.0), high=(2.0, 2.0, 2.0))  # large enough that nothing is clipped
    agent = DDPG(*obs_scaling(ws), 4, DDPGConfig(actor_head=head, max_offset=0.3), seed=2)
    last = agent.actor.net[-2]
    with torch.no_grad():
        last.weight.zero_()
        last.bias.copy_(torch.tensor([0.1, -0.2, 0.3, 0.5]))
    spec = dataclasses.replace(load_robot(), workspace=ws)  # a file for the large box; loaded without an arm
    pol = ExportedPolicy.load(export_actor(agent.actor, tmp_path / "policy.npz", spec, TaskConfig(), 0.1))
    obs = _random_obs(load_robot().workspace, 300)
    obs[:, 4] = np.random.default_rng(3).choice([0.0, 0.2, 0.4, 0.6, 0.8, 1.0], 300)
    before = obs[:, 4] <= 0.5
    expected = np.where(before[:, None], obs[:, base[0]: base[0] + 3], obs[:, base[1]: base[1] + 3]) + 0.3 * np.tanh([0.1, -0.2, 0.3])
    with torch.no_grad():
        from_torch = ws.to_cartesian(agent.actor(torch.as_tensor(obs)).numpy()[:, :3])
    assert np.allclose(from_torch, expected, atol=1e-5)
    assert np.allclose(ws.to_cartesian(pol.batch(obs)[:, :3]), expected, atol=1e-5)


@pytest.mark.parametrize("head", ANCHOR_HEADS)
def test_anchor_file_without_its_carry_layer_refused(tmp_path, head):
    _, path = _anchor_policy(tmp_path, head)
    bad = _rewrite(path, tmp_path / "bad.npz", lambda a: a.pop("W0_carry"))
    with pytest.raises(PolicyFileError, match="W0_carry"):
        ExportedPolicy.load(bad)
    bad = _rewrite(path, tmp_path / "short.npz", lambda a: a.update(b0_carry=np.zeros(3)))
    with pytest.raises(PolicyFileError, match="carry layer"):
        ExportedPolicy.load(bad)
