"""The IK step of N worlds in one compiled call: ``ik_kernel`` (Algorithm 1, as ``Kinematics.ik``
runs it) in a loop over the worlds, which pays Python's per-call cost once for all of them."""

from __future__ import annotations

import numba
import numpy as np

from rayreach.sim.ik_kernel import ik_kernel, rotvec_matrix
from rayreach.sim.kinematics import IKParams, Kinematics


def solve_steps(kin: Kinematics, params: IKParams, delta: np.ndarray, q: np.ndarray, frames: np.ndarray,
                ee_pos: np.ndarray, ee_rot: np.ndarray, converged: np.ndarray) -> None:
    """Take the pose step ``delta`` (N, 6: m, then a rotation vector in rad) in every
    world: IK from the world's joints, then ``q``, ``frames``, ``ee_pos`` and
    ``ee_rot`` (all (N, ...)) hold the solution and ``converged`` (N,) whether it met the
    tolerance, as ``ReachEnv.solve`` followed by ``advance(taken=True)``."""
    _solve_steps(*kin.kernel_args(params), delta, q, frames, ee_pos, ee_rot, converged)


# ---------------------------------------------------------------------- compiled parts
@numba.njit(cache=True)
def _solve_steps(world0, before, axis, after, lower, upper, tool_length, damping2, scale, gain,
                 tolerance, max_iterations, delta, q, frames, ee_pos, ee_rot,
                 converged):  # pragma: no cover - compiled
    step_rot = np.empty((3, 3))
    target_rot = np.empty((3, 3))
    target_pos = np.empty(3)
    result = np.empty(4)
    for w in range(q.shape[0]):
        rotvec_matrix(delta[w, 3:], step_rot)
        for i in range(3):  # ReachEnv.solve: the step's rotation applied to the tool's orientation
            target_pos[i] = ee_pos[w, i] + delta[w, i]
            for j in range(3):
                target_rot[i, j] = step_rot[i, 0] * ee_rot[w, 0, j] + step_rot[i, 1] * ee_rot[w, 1, j] \
                    + step_rot[i, 2] * ee_rot[w, 2, j]
        ik_kernel(world0, before, axis, after, lower, upper, tool_length, damping2, scale, gain,
                  tolerance, max_iterations, target_pos, target_rot, 6, q[w], frames[w], result)
        converged[w] = result[0] > 0.5
        tip = frames[w, q.shape[1]]
        for i in range(3):
            ee_pos[w, i] = tip[i, 2] * tool_length + tip[i, 3]
            for j in range(3):
                ee_rot[w, i, j] = tip[i, j]
