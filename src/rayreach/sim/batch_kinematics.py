"""Forward kinematics and the DLS IK step of ``Kinematics`` for N worlds in one compiled call.

The per-world arithmetic is ``rayreach.sim.kinematics``' (paper eqs. 1-2 and Algorithm 1,
with its error-scaled damping), written as scalar loops that numba compiles: numpy's
per-call overhead on 4 x 4 and 6 x 6 arrays is most of what a single environment's IK costs,
and a loop over worlds pays it once. ``tests/test_batched_env.py`` holds the two to the same
joint angles.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from rayreach.sim.kinematics import IKParams, Kinematics

N_FRAMES = 7
"""DH frames 0..6 of a 6-axis arm (6: the flange)."""


@dataclass(frozen=True)
class ChainArrays:
    """One robot's DH chain, base pose and tool as the kernels read them."""

    world_dh0: np.ndarray
    d: np.ndarray
    a: np.ndarray
    ca: np.ndarray
    sa: np.ndarray
    offset: np.ndarray
    sign: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    tool_length: float

    @classmethod
    def of(cls, kin: Kinematics) -> "ChainArrays":
        return cls(kin.world_dh0.copy(), kin._d.copy(), kin._a.copy(), kin._ca.copy(), kin._sa.copy(),
                   kin._offset.copy(), kin._sign.copy(), kin.lower.copy(), kin.upper.copy(),
                   float(kin.flange_tool[2, 3]))


def solve_steps(chain: ChainArrays, params: IKParams, delta: np.ndarray, q: np.ndarray, frames: np.ndarray,
                ee_pos: np.ndarray, ee_rot: np.ndarray, active: np.ndarray, converged: np.ndarray) -> None:
    """Take the pose step ``delta`` (N, 6: m, then a rotation vector in rad) in every
    ``active`` world: IK from the world's joints, then ``q``, ``frames``, ``ee_pos`` and
    ``ee_rot`` (all (N, ...)) hold the solution and ``converged`` (N,) whether it met the
    tolerance, as ``ReachEnv.solve`` followed by ``advance(taken=True)``."""
    scale = -1.0 if params.damping_scale is None else float(params.damping_scale)
    _solve_steps(chain.world_dh0, chain.d, chain.a, chain.ca, chain.sa, chain.offset, chain.sign, chain.lower,
                 chain.upper, chain.tool_length, float(params.damping) ** 2, scale,
                 params.delta_int / params.delta_dif, float(params.tolerance), int(params.max_iterations),
                 delta, q, frames, ee_pos, ee_rot, active, converged)


def chain_frames(chain: ChainArrays, q: np.ndarray, frames: np.ndarray) -> None:
    """DH frames (N, 7, 4, 4) of joint angles ``q`` (N, 6), written into ``frames``."""
    for i in range(len(q)):
        _frames(chain.world_dh0, chain.d, chain.a, chain.ca, chain.sa, chain.offset, chain.sign, q[i], frames[i])


# ---------------------------------------------------------------------- compiled parts
@numba.njit(cache=True)
def _frames(world_dh0, d, a, ca, sa, offset, sign, q, out):  # pragma: no cover - compiled
    out[0] = world_dh0
    for i in range(len(d)):
        theta = sign[i] * q[i] + offset[i]
        ct, st = np.cos(theta), np.sin(theta)
        m00, m01, m02, m03 = ct, -st * ca[i], st * sa[i], a[i] * ct
        m10, m11, m12, m13 = st, ct * ca[i], -ct * sa[i], a[i] * st
        m21, m22, m23 = sa[i], ca[i], d[i]
        f = out[i]
        g = out[i + 1]
        for r in range(3):
            f0, f1, f2, f3 = f[r, 0], f[r, 1], f[r, 2], f[r, 3]
            g[r, 0] = f0 * m00 + f1 * m10
            g[r, 1] = f0 * m01 + f1 * m11 + f2 * m21
            g[r, 2] = f0 * m02 + f1 * m12 + f2 * m22
            g[r, 3] = f0 * m03 + f1 * m13 + f2 * m23 + f3
        g[3, 0] = 0.0
        g[3, 1] = 0.0
        g[3, 2] = 0.0
        g[3, 3] = 1.0


@numba.njit(cache=True)
def _rotvec(r, out):  # pragma: no cover - compiled
    """``transforms.matrix_to_rotvec`` of the 3 x 3 ``r`` into ``out``."""
    cos = (r[0, 0] + r[1, 1] + r[2, 2] - 1.0) / 2.0
    cos = min(1.0, max(-1.0, cos))
    v0, v1, v2 = r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]
    if cos > 1.0 - 1e-10:
        out[0], out[1], out[2] = 0.5 * v0, 0.5 * v1, 0.5 * v2
        return
    angle = np.arccos(cos)
    if angle < np.pi - 1e-4:
        k = angle / (2.0 * np.sin(angle))
        out[0], out[1], out[2] = k * v0, k * v1, k * v2
        return
    sym = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            sym[i, j] = ((r[i, j] + r[j, i]) / 2.0 - (cos if i == j else 0.0)) / (1.0 - cos)
    i = 0
    for j in range(1, 3):
        if sym[j, j] > sym[i, i]:
            i = j
    norm = np.sqrt(max(sym[i, i], 1e-300))
    s = 1.0 if (sym[0, i] * v0 + sym[1, i] * v1 + sym[2, i] * v2) >= 0 else -1.0
    for j in range(3):
        out[j] = s * angle * sym[j, i] / norm


@numba.njit(cache=True)
def _rotvec_matrix(v, out):  # pragma: no cover - compiled
    """``transforms.rotvec_to_matrix``: Rodrigues' formula."""
    angle = np.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
    for i in range(3):
        for j in range(3):
            out[i, j] = 1.0 if i == j else 0.0
    if angle < 1e-12:
        return
    k0, k1, k2 = v[0] / angle, v[1] / angle, v[2] / angle
    kx = np.array([[0.0, -k2, k1], [k2, 0.0, -k0], [-k1, k0, 0.0]])
    s, c = np.sin(angle), 1.0 - np.cos(angle)
    for i in range(3):
        for j in range(3):
            kk = kx[i, 0] * kx[0, j] + kx[i, 1] * kx[1, j] + kx[i, 2] * kx[2, j]
            out[i, j] += s * kx[i, j] + c * kk


@numba.njit(cache=True)
def _error(frames, tool_length, target_pos, target_rot, rel, out):  # pragma: no cover - compiled
    """6-D pose error of the tool tip (``Kinematics._pose_error``) into ``out``."""
    f = frames[6]
    for j in range(3):
        out[j] = target_pos[j] - (f[j, 2] * tool_length + f[j, 3])
    for i in range(3):  # target_rot @ ee_rot^T
        for j in range(3):
            rel[i, j] = target_rot[i, 0] * f[j, 0] + target_rot[i, 1] * f[j, 1] + target_rot[i, 2] * f[j, 2]
    _rotvec(rel, out[3:])


@numba.njit(cache=True)
def _solve(m, b, x):  # pragma: no cover - compiled
    """x = m^-1 b by Gaussian elimination with partial pivoting (LAPACK's ``gesv``, which
    ``np.linalg.solve`` calls; numba's own binding of it would need scipy); ``m`` is spent."""
    n = len(b)
    for i in range(n):
        x[i] = b[i]
    for c in range(n):
        pivot = c
        for r in range(c + 1, n):
            if abs(m[r, c]) > abs(m[pivot, c]):
                pivot = r
        if pivot != c:
            for k in range(n):
                m[c, k], m[pivot, k] = m[pivot, k], m[c, k]
            x[c], x[pivot] = x[pivot], x[c]
        for r in range(c + 1, n):
            f = m[r, c] / m[c, c]
            for k in range(c + 1, n):
                m[r, k] -= f * m[c, k]
            x[r] -= f * x[c]
    for c in range(n - 1, -1, -1):
        s = x[c]
        for k in range(c + 1, n):
            s -= m[c, k] * x[k]
        x[c] = s / m[c, c]


@numba.njit(cache=True)
def _solve_steps(world_dh0, d, a, ca, sa, offset, sign, lower, upper, tool_length, damping2, scale, gain,
                 tolerance, max_iterations, delta, q, frames, ee_pos, ee_rot, active,
                 converged):  # pragma: no cover - compiled
    n = len(d)
    step_rot = np.empty((3, 3))
    target_rot = np.empty((3, 3))
    target_pos = np.empty(3)
    rel = np.empty((3, 3))
    error = np.empty(6)
    jac = np.empty((6, n))
    system = np.empty((6, 6))
    x = np.empty(6)
    for w in range(q.shape[0]):
        if not active[w]:
            continue
        fr = frames[w]
        _rotvec_matrix(delta[w, 3:], step_rot)
        for i in range(3):
            target_pos[i] = ee_pos[w, i] + delta[w, i]
            for j in range(3):
                target_rot[i, j] = step_rot[i, 0] * ee_rot[w, 0, j] + step_rot[i, 1] * ee_rot[w, 1, j] \
                    + step_rot[i, 2] * ee_rot[w, 2, j]
        _error(fr, tool_length, target_pos, target_rot, rel, error)
        norm = np.sqrt(np.sum(error * error))
        iterations = 0
        while True:
            tip = fr[6]
            p0 = tip[0, 2] * tool_length + tip[0, 3]
            p1 = tip[1, 2] * tool_length + tip[1, 3]
            p2 = tip[2, 2] * tool_length + tip[2, 3]
            for j in range(n):
                z0, z1, z2 = fr[j, 0, 2] * sign[j], fr[j, 1, 2] * sign[j], fr[j, 2, 2] * sign[j]
                r0, r1, r2 = p0 - fr[j, 0, 3], p1 - fr[j, 1, 3], p2 - fr[j, 2, 3]
                jac[0, j] = z1 * r2 - z2 * r1
                jac[1, j] = z2 * r0 - z0 * r2
                jac[2, j] = z0 * r1 - z1 * r0
                jac[3, j], jac[4, j], jac[5, j] = z0, z1, z2
            lam2 = damping2 if scale < 0 or norm >= scale else damping2 * norm / scale
            for i in range(6):
                for j in range(6):
                    s = 0.0
                    for k in range(n):
                        s += jac[i, k] * jac[j, k]
                    system[i, j] = s + (lam2 if i == j else 0.0)
            _solve(system, error, x)
            for k in range(n):
                s = 0.0
                for i in range(6):
                    s += jac[i, k] * x[i]
                q[w, k] = min(max(q[w, k] + gain * s, lower[k]), upper[k])
            _frames(world_dh0, d, a, ca, sa, offset, sign, q[w], fr)
            _error(fr, tool_length, target_pos, target_rot, rel, error)
            iterations += 1
            norm = np.sqrt(np.sum(error * error))
            if norm <= tolerance or iterations >= max_iterations:
                break
        converged[w] = norm <= tolerance
        tip = fr[6]
        for i in range(3):
            ee_pos[w, i] = tip[i, 2] * tool_length + tip[i, 3]
            for j in range(3):
                ee_rot[w, i, j] = tip[i, j]
