"""Export to the numpy policy file; the deploy loader matches torch and refuses bad files."""

import json

import numpy as np
import pytest
import torch

from mrguide.deploy.policy import ExportedPolicy, PolicyFileError
from mrguide.policies.ddpg import DDPG, DDPGConfig
from mrguide.policies.export import export_actor
from mrguide.policies.train import obs_scaling
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
