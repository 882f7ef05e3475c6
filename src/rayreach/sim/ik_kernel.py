"""Algorithm 1 (damped-least-squares IK) and the forward kinematics it iterates, compiled.

``Kinematics.ik`` and the batched environment's step both run this one implementation: the
arithmetic of ``Kinematics``' numpy forward kinematics and Jacobian over the joint chain
(``rayreach.robots.chain``: the paper's DH table, eqs. 1-2, or the URDF's joints), as
scalar loops that numba compiles, since numpy's per-call overhead on 4 x 4 and 6 x 6 arrays
was most of what an IK call cost. ``tests/test_kinematics.py`` holds it to PyBullet and to
the numpy Jacobian.
"""

from __future__ import annotations

import numba
import numpy as np


@numba.njit(cache=True)
def frames_kernel(world0, before, axis, after, q, out):  # pragma: no cover - compiled
    """Frames 0..n of the chain at ``q`` into ``out``: frame i = frame i-1 @ before_i @
    Rot(axis_i, q_i) @ after_i (``rayreach.robots.chain``), Rodrigues' formula for the turn."""
    out[0] = world0
    g = np.empty((3, 4))
    h = np.empty((3, 4))
    rot = np.empty((3, 3))
    for i in range(len(q)):
        u0, u1, u2 = axis[i, 0], axis[i, 1], axis[i, 2]
        c, s = np.cos(q[i]), np.sin(q[i])
        v = 1.0 - c
        rot[0, 0], rot[0, 1], rot[0, 2] = c + v * u0 * u0, v * u0 * u1 - s * u2, v * u0 * u2 + s * u1
        rot[1, 0], rot[1, 1], rot[1, 2] = v * u1 * u0 + s * u2, c + v * u1 * u1, v * u1 * u2 - s * u0
        rot[2, 0], rot[2, 1], rot[2, 2] = v * u2 * u0 - s * u1, v * u2 * u1 + s * u0, c + v * u2 * u2
        f, b, a, o = out[i], before[i], after[i], out[i + 1]
        for r in range(3):
            for col in range(4):
                g[r, col] = f[r, 0] * b[0, col] + f[r, 1] * b[1, col] + f[r, 2] * b[2, col]
            g[r, 3] += f[r, 3]
            for col in range(3):
                h[r, col] = g[r, 0] * rot[0, col] + g[r, 1] * rot[1, col] + g[r, 2] * rot[2, col]
            h[r, 3] = g[r, 3]
            for col in range(4):
                o[r, col] = h[r, 0] * a[0, col] + h[r, 1] * a[1, col] + h[r, 2] * a[2, col]
            o[r, 3] += h[r, 3]
        o[3, 0] = 0.0
        o[3, 1] = 0.0
        o[3, 2] = 0.0
        o[3, 3] = 1.0


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
def rotvec_matrix(v, out):  # pragma: no cover - compiled
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
def _error(frames, tool_length, target_pos, target_rot, rows, rel, out):  # pragma: no cover - compiled
    """Pose error of the tool tip, position then (``rows`` 6) rotation vector, into ``out``."""
    f = frames[len(frames) - 1]
    for j in range(3):
        out[j] = target_pos[j] - (f[j, 2] * tool_length + f[j, 3])
    if rows == 3:
        return
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
def ik_kernel(world0, before, axis, after, lower, upper, tool_length, damping2, scale, gain,
              tolerance, max_iterations, target_pos, target_rot, rows, q, frames,
              result):  # pragma: no cover - compiled
    """Algorithm 1 from ``q`` (whose chain frames ``frames`` holds) towards ``target_pos`` and, for
    ``rows`` 6, ``target_rot``; ``rows`` 3 solves for the position only. ``q`` and ``frames``
    end at the solution; ``result`` gets (converged, iterations, position error, orientation
    error)."""
    n = len(q)
    rel = np.empty((3, 3))
    error = np.empty(6)
    jac = np.empty((6, n))
    system = np.empty((rows, rows))
    x = np.empty(rows)
    _error(frames, tool_length, target_pos, target_rot, rows, rel, error)
    norm = np.sqrt(np.sum(error[:rows] * error[:rows]))
    iterations = 0
    while True:  # do ... while ||x_e|| > epsilon
        tip = frames[n]
        p0 = tip[0, 2] * tool_length + tip[0, 3]
        p1 = tip[1, 2] * tool_length + tip[1, 3]
        p2 = tip[2, 2] * tool_length + tip[2, 3]
        for j in range(n):  # geometric Jacobian: z_j x (p - o_j) over z_j, the joint's world axis and origin
            f, b = frames[j], before[j]
            w0 = b[0, 0] * axis[j, 0] + b[0, 1] * axis[j, 1] + b[0, 2] * axis[j, 2]
            w1 = b[1, 0] * axis[j, 0] + b[1, 1] * axis[j, 1] + b[1, 2] * axis[j, 2]
            w2 = b[2, 0] * axis[j, 0] + b[2, 1] * axis[j, 1] + b[2, 2] * axis[j, 2]
            z0 = f[0, 0] * w0 + f[0, 1] * w1 + f[0, 2] * w2
            z1 = f[1, 0] * w0 + f[1, 1] * w1 + f[1, 2] * w2
            z2 = f[2, 0] * w0 + f[2, 1] * w1 + f[2, 2] * w2
            o0 = f[0, 0] * b[0, 3] + f[0, 1] * b[1, 3] + f[0, 2] * b[2, 3] + f[0, 3]
            o1 = f[1, 0] * b[0, 3] + f[1, 1] * b[1, 3] + f[1, 2] * b[2, 3] + f[1, 3]
            o2 = f[2, 0] * b[0, 3] + f[2, 1] * b[1, 3] + f[2, 2] * b[2, 3] + f[2, 3]
            r0, r1, r2 = p0 - o0, p1 - o1, p2 - o2
            jac[0, j] = z1 * r2 - z2 * r1
            jac[1, j] = z2 * r0 - z0 * r2
            jac[2, j] = z0 * r1 - z1 * r0
            jac[3, j], jac[4, j], jac[5, j] = z0, z1, z2
        lam2 = damping2 if scale < 0 or norm >= scale else damping2 * norm / scale
        for i in range(rows):
            for j in range(rows):
                s = 0.0
                for k in range(n):
                    s += jac[i, k] * jac[j, k]
                system[i, j] = s + (lam2 if i == j else 0.0)
        _solve(system, error[:rows], x)
        for k in range(n):
            s = 0.0
            for i in range(rows):
                s += jac[i, k] * x[i]
            q[k] = min(max(q[k] + gain * s, lower[k]), upper[k])
        frames_kernel(world0, before, axis, after, q, frames)
        _error(frames, tool_length, target_pos, target_rot, rows, rel, error)
        iterations += 1
        norm = np.sqrt(np.sum(error[:rows] * error[:rows]))
        if norm <= tolerance or iterations >= max_iterations:
            break
    result[0] = 1.0 if norm <= tolerance else 0.0
    result[1] = iterations
    result[2] = np.sqrt(error[0] * error[0] + error[1] * error[1] + error[2] * error[2])
    result[3] = np.sqrt(error[3] * error[3] + error[4] * error[4] + error[5] * error[5]) if rows == 6 else 0.0
