"""Forward kinematics over the joint chain (paper eqs. 1-2 for a DH table, the URDF's joints
otherwise: ``rayreach.robots.chain``), the geometric Jacobian and damped-least-squares inverse
kinematics (paper Algorithm 1), compiled where it is hot.

Frames are in the world: the robot's base pose and the chain's root (the fixed URDF-to-DH
rotation of a DH table) are folded into frame 0, and the tool offset into the end-effector frame, so
``Kinematics.fk(q)`` is directly comparable to PyBullet's pose of the tool tip.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rayreach.robots.chain import robot_chain
from rayreach.robots.spec import RobotSpec
from rayreach.sim.ik_kernel import frames_kernel, ik_kernel
from rayreach.sim.transforms import pose_matrix, rotvec_to_matrix, rpy_to_matrix


@dataclass(frozen=True)
class IKParams:
    """Parameters of Algorithm 1.

    The update is ``q += delta_int * J^T (J J^T + damping^2 I)^-1 (x_e / delta_dif)``, so
    only the ratio ``delta_int / delta_dif`` matters; with both equal (the default) each
    iteration is a damped Gauss-Newton step. ``tolerance`` bounds the norm of the 6-D
    error (metres and radians together; 3-D for position-only targets).
    """

    damping: float = 0.05
    """lambda: trades accuracy for bounded joint steps near singularities."""
    damping_scale: float | None = 0.05
    """Below this error norm, lambda^2 shrinks in proportion (lambda^2 * ||x_e|| / scale), so the
    last iterations become Gauss-Newton steps and converge fast even at singular targets; far
    from the target lambda is the paper's constant. None: constant lambda throughout."""
    delta_int: float = 0.01
    """Integration step Delta_int."""
    delta_dif: float = 0.01
    """Differentiation step Delta_dif."""
    tolerance: float = 1e-5
    """epsilon: stop when ||x_e|| is at most this."""
    max_iterations: int = 100
    """Give up (status ``converged=False``) after this many iterations."""


STEP_IK = IKParams(tolerance=1e-4, max_iterations=10)
"""IK per control step: 0.1 mm is ample for a 5 mm step, which one iteration nearly always
reaches (the damping shrinks for small errors); an unconverged step still moves."""


@dataclass(frozen=True)
class IKResult:
    q: np.ndarray
    converged: bool
    iterations: int
    position_error: float
    """Euclidean distance between reached and target position, m."""
    orientation_error: float
    """Angle between reached and target orientation, rad (0 for position-only targets)."""
    frames: np.ndarray
    """DH frames at ``q`` (see :meth:`Kinematics.frames`), so callers need not recompute them."""


class Kinematics:
    """Kinematics of one robot placed at a base pose in the world."""

    def __init__(
        self,
        spec: RobotSpec,
        base_position: tuple[float, float, float] | None = None,
        base_rpy: tuple[float, float, float] | None = None,
    ) -> None:
        self.spec = spec
        position = spec.base_position if base_position is None else base_position
        rpy = spec.base_rpy if base_rpy is None else base_rpy
        self.chain = robot_chain(spec)
        self.world0 = pose_matrix(position, rpy_to_matrix(rpy)) @ self.chain.root
        """World pose of frame 0: the base pose, then the chain's root (the DH base rotation)."""
        self.flange_tool = pose_matrix((0.0, 0.0, spec.tool.length), np.eye(3))
        self.lower = spec.lower_array
        self.upper = spec.upper_array
        self._eye = {3: np.eye(3), 6: np.eye(6)}
        # each joint's axis and origin in the frame before it, for the Jacobian
        self._joint_axis = np.einsum("nij,nj->ni", self.chain.before[:, :3, :3], self.chain.axis)
        self._joint_origin = self.chain.before[:, :3, 3].copy()

    @property
    def base_turn_sign(self) -> float:
        """+1 when a positive first joint turns the arm counter-clockwise about frame 0's z axis."""
        return 1.0 if self._joint_axis[0, 2] >= 0.0 else -1.0

    # ------------------------------------------------------------------ forward kinematics
    def frames(self, q: np.ndarray) -> np.ndarray:
        """World poses of frames 0..n (frame n is the flange), shape (n + 1, 4, 4): paper eq. 1
        over the chain's joints (``rayreach.robots.chain``)."""
        q = np.asarray(q, dtype=float)
        if q.shape != (self.chain.n_joints,):  # the compiled loop would read past the chain
            raise ValueError(f"{self.spec.name} has {self.chain.n_joints} joints; got joint angles of shape {q.shape}")
        out = np.empty((self.chain.n_joints + 1, 4, 4))
        frames_kernel(self.world0, self.chain.before, self.chain.axis, self.chain.after, q, out)
        return out

    def joint_origin(self, frames: np.ndarray, i: int) -> np.ndarray:
        """World position of joint ``i``'s origin (0-based) in the arm's ``frames``, m (3,)."""
        return frames[i, :3, :3] @ self._joint_origin[i] + frames[i, :3, 3]

    def fk(self, q: np.ndarray) -> np.ndarray:
        """World pose (4x4) of the end effector, the tool tip (paper eq. 1)."""
        return self.frames(q)[-1] @ self.flange_tool

    def ee_from_frames(self, frames: np.ndarray) -> np.ndarray:
        return frames[-1] @ self.flange_tool

    def jacobian(self, frames: np.ndarray, point: np.ndarray | None = None) -> np.ndarray:
        """Geometric Jacobian (6 x n, linear rows first) of ``point`` (default: the tool tip)."""
        if point is None:
            point = self.ee_from_frames(frames)[:3, 3]
        rot = frames[:-1, :3, :3]
        z = np.einsum("nij,nj->in", rot, self._joint_axis)  # (3, n): joint axes in the world
        origin = np.einsum("nij,nj->in", rot, self._joint_origin) + frames[:-1, :3, 3].T
        r = point[:, None] - origin  # (3, n): joint to point
        jac = np.empty((6, z.shape[1]))
        jac[0] = z[1] * r[2] - z[2] * r[1]  # z x r, written out: np.cross is slow on tiny arrays
        jac[1] = z[2] * r[0] - z[0] * r[2]
        jac[2] = z[0] * r[1] - z[1] * r[0]
        jac[3:] = z
        return jac

    # ------------------------------------------------------------------ inverse kinematics
    def ik(
        self,
        target_position: np.ndarray,
        target_rotation: np.ndarray | None,
        q_start: np.ndarray,
        params: IKParams = IKParams(),
        start_frames: np.ndarray | None = None,
    ) -> IKResult:
        """Damped-least-squares IK (Algorithm 1) from ``q_start`` towards a world pose.

        ``target_rotation=None`` solves for the position only. Joint limits are enforced
        by clipping every iterate. The paper writes the error as ``x_c - x_d``; the update
        must move towards the target, so the error used here is ``x_d - x_c``.
        Never raises on failure: ``converged`` tells whether ``q`` meets the tolerance.
        ``start_frames`` may pass ``frames(q_start)`` when the caller has them already (the
        hot path of the environment); ``q_start`` must then lie within the joint limits.
        The iterations run compiled (``rayreach.sim.ik_kernel``), on the same forward
        kinematics and Jacobian as ``frames`` and ``jacobian``.
        """
        target_position = np.asarray(target_position, dtype=float)
        position_only = target_rotation is None
        if start_frames is None:
            q = np.minimum(np.maximum(np.asarray(q_start, dtype=float), self.lower), self.upper)
            frames = self.frames(q)
        else:
            q, frames = np.array(q_start, dtype=float), np.array(start_frames, dtype=float)
        rotation = self._eye[3] if position_only else np.ascontiguousarray(target_rotation, dtype=float)
        result = np.empty(4)
        ik_kernel(*self.kernel_args(params), target_position, rotation, 3 if position_only else 6, q, frames,
                  result)
        return IKResult(q=q, converged=bool(result[0] > 0.5), iterations=int(result[1]),
                        position_error=float(result[2]), orientation_error=float(result[3]), frames=frames)

    def step_ik(self, delta: np.ndarray, q: np.ndarray, frames: np.ndarray, ee_pos: np.ndarray,
                ee_rot: np.ndarray, params: IKParams, keep_orientation: bool = True) -> IKResult:
        """The paper's control step: IK for the end-effector step ``delta`` (dx, dy, dz in m,
        then a rotation vector in rad, applied to the tool's orientation) from ``q``, whose
        frames and tool pose are ``frames``, ``ee_pos`` and ``ee_rot``; ``keep_orientation``
        False solves for the position only. Simulation and a real arm's controller share it."""
        target_rot = rotvec_to_matrix(delta[3:]) @ ee_rot if keep_orientation else None
        return self.ik(ee_pos + delta[:3], target_rot, q, params, start_frames=frames)

    def kernel_args(self, params: IKParams) -> tuple:
        """The chain and ``params`` as ``ik_kernel`` takes them, up to its target: frame 0's
        pose, the chain, joint limits, tool length, lambda^2, damping scale (-1: none), gain,
        tolerance and iteration limit."""
        scale = -1.0 if params.damping_scale is None else float(params.damping_scale)
        return (self.world0, self.chain.before, self.chain.axis, self.chain.after, self.lower,
                self.upper, float(self.flange_tool[2, 3]), float(params.damping) ** 2, scale,
                params.delta_int / params.delta_dif, float(params.tolerance), int(params.max_iterations))
