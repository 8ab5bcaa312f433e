"""Pinocchio FK/IK against PyBullet and over the workspace."""

import numpy as np
import pybullet as pb
import pytest

from mrguide.motion.kinematics import IKError, Kinematics
from mrguide.robot import R_TOOL_DOWN, load_robot
from mrguide.twin.config import TwinConfig
from mrguide.twin.scene import Scene


@pytest.fixture(scope="module")
def spec():
    return load_robot()


@pytest.fixture(scope="module")
def kin(spec):
    return Kinematics(spec)


def test_fk_matches_pybullet_link_pose(spec, kin):
    scene = Scene(spec, TwinConfig())
    rng = np.random.default_rng(1)
    try:
        for _ in range(50):
            q = rng.uniform(spec.q_lower, spec.q_upper)
            for j, qj in zip(scene.joint_ids, q):
                pb.resetJointState(scene.robot, j, qj, physicsClientId=scene.client)
            pos, orn = scene.tcp_pose_pybullet()
            T = kin.fk(q)
            assert np.linalg.norm(T[:3, 3] - pos) < 1e-3
            R_pb = np.array(pb.getMatrixFromQuaternion(orn)).reshape(3, 3)
            assert np.allclose(T[:3, :3], R_pb, atol=1e-3)
    finally:
        scene.close()


def test_ik_round_trips_over_workspace_grid(spec, kin):
    ws = spec.workspace
    axes = [np.linspace(ws.lo[i], ws.hi[i], 6) for i in range(3)]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    for p in grid:
        q = kin.ik(p, spec.q_home)
        assert spec.within_limits(q), p
        T = kin.fk(q)
        assert np.linalg.norm(T[:3, 3] - p) < 1e-3, p
        assert np.allclose(T[:3, :3], R_TOOL_DOWN, atol=1e-2), p


@pytest.mark.parametrize("p", [(1.5, 0.0, 0.2), (0.0, 0.0, -0.5), (0.05, 0.0, 0.1)])
def test_ik_refuses_unreachable_targets(spec, kin, p):
    with pytest.raises(IKError, match="unreachable"):
        kin.ik(np.array(p), spec.q_home)


def test_ik_refuses_non_finite(spec, kin):
    with pytest.raises(IKError, match="finite"):
        kin.ik(np.array([np.nan, 0.0, 0.2]), spec.q_home)
