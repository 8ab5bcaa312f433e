"""Pinocchio forward and inverse kinematics of the arm's TCP (suction-cup lip, pointing down)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from mrguide.robot import R_TOOL_DOWN, RobotSpec


class IKError(RuntimeError):
    """The IK target cannot be reached within the joint limits (or the input is not finite)."""


class Kinematics:
    """FK and damped-least-squares IK for a position target with a fixed tool orientation."""

    TCP_FRAME = "tcp"

    def __init__(
        self,
        spec: RobotSpec,
        tol_position: float = 1e-4,
        tol_rotation: float = 1e-3,
        max_iterations: int = 60,
        damping: float = 1e-4,
    ):
        self.spec = spec
        self.model = pin.buildModelFromUrdf(str(spec.urdf_path))
        names = tuple(self.model.names[1:])
        if names != spec.joint_names:
            raise ValueError(f"URDF joints {names} differ from the robot spec's {spec.joint_names}")
        flange = self.model.getFrameId(spec.flange_frame)
        parent = self.model.frames[flange]
        placement = parent.placement * pin.SE3(spec.T_flange_tcp[:3, :3], spec.T_flange_tcp[:3, 3])
        frame = pin.Frame(self.TCP_FRAME, parent.parentJoint, flange, placement, pin.FrameType.OP_FRAME)
        self.tcp_id = self.model.addFrame(frame)
        self.data = self.model.createData()
        self.tol_position = tol_position
        self.tol_rotation = tol_rotation
        self.max_iterations = max_iterations
        self.damping = damping

    def fk(self, q: np.ndarray) -> np.ndarray:
        """T_base_tcp (4x4) at joint configuration q."""
        pin.framesForwardKinematics(self.model, self.data, np.asarray(q, dtype=float))
        return self.data.oMf[self.tcp_id].homogeneous.copy()

    def tcp_position(self, q: np.ndarray) -> np.ndarray:
        """TCP position (3,) in the base frame."""
        pin.framesForwardKinematics(self.model, self.data, np.asarray(q, dtype=float))
        return self.data.oMf[self.tcp_id].translation.copy()

    def ik(self, p_target: np.ndarray, q_seed: np.ndarray, R_target: np.ndarray = R_TOOL_DOWN) -> np.ndarray:
        """Joint configuration placing the TCP at `p_target` with orientation `R_target`.

        Damped least squares on the SE(3) log error in the TCP frame, warm-started at `q_seed`, with
        the joint limits enforced at every iteration; if the warm start gets stuck (a posture far from
        the target's), the solve is repeated from the home configuration. Raises IKError if the pose is
        not reached from either.
        """
        try:
            return self._solve(p_target, q_seed, R_target)
        except IKError:
            if np.all(np.isfinite(np.asarray(q_seed, dtype=float))):
                return self._solve(p_target, self.spec.q_home, R_target)
            raise

    def _solve(self, p_target: np.ndarray, q_seed: np.ndarray, R_target: np.ndarray) -> np.ndarray:
        p_target = np.asarray(p_target, dtype=float)
        q = np.clip(np.asarray(q_seed, dtype=float), self.spec.q_lower, self.spec.q_upper)
        if p_target.shape != (3,) or not np.all(np.isfinite(p_target)) or not np.all(np.isfinite(q)):
            raise IKError(f"IK needs a finite 3-vector target and a finite seed, got {p_target} / {q_seed}")
        target = pin.SE3(np.asarray(R_target, dtype=float), p_target)
        model, data, fid = self.model, self.data, self.tcp_id
        eye6 = np.eye(6)
        for _ in range(self.max_iterations):
            pin.framesForwardKinematics(model, data, q)
            err = pin.log6(data.oMf[fid].actInv(target)).vector
            if np.linalg.norm(err[:3]) < self.tol_position and np.linalg.norm(err[3:]) < self.tol_rotation:
                return q
            J = pin.computeFrameJacobian(model, data, q, fid, pin.LOCAL)
            dq = J.T @ np.linalg.solve(J @ J.T + self.damping * eye6, err)
            q = np.clip(q + dq, self.spec.q_lower, self.spec.q_upper)
        pin.framesForwardKinematics(model, data, q)
        M = data.oMf[fid]
        pos_err = float(np.linalg.norm(M.translation - p_target))
        rot_err = float(np.linalg.norm(pin.log3(M.rotation.T @ target.rotation)))
        if pos_err < 10 * self.tol_position and rot_err < 10 * self.tol_rotation:
            return q
        raise IKError(
            f"target {np.round(p_target, 4).tolist()} unreachable with the tool pointing down within the "
            f"joint limits (best residual {pos_err * 1e3:.1f} mm, {np.degrees(rot_err):.2f} deg)"
        )
