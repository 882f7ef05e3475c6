"""Rotation helpers in PyBullet's conventions (roll-pitch-yaw = extrinsic x-y-z, quaternions xyzw)."""

from __future__ import annotations

import math

import numpy as np


def rpy_to_matrix(rpy: np.ndarray | tuple[float, float, float]) -> np.ndarray:
    """R = Rz(yaw) @ Ry(pitch) @ Rx(roll), as ``pybullet.getQuaternionFromEuler`` defines it."""
    r, p, y = (float(v) for v in rpy)
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return np.array(
        [
            [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
            [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
            [-sp, cp * sr, cp * cr],
        ]
    )


def matrix_to_rpy(rot: np.ndarray) -> np.ndarray:
    """Inverse of :func:`rpy_to_matrix` with pitch in [-pi/2, pi/2]."""
    pitch = math.asin(max(-1.0, min(1.0, -rot[2, 0])))
    if abs(rot[2, 0]) < 1.0 - 1e-12:
        roll = math.atan2(rot[2, 1], rot[2, 2])
        yaw = math.atan2(rot[1, 0], rot[0, 0])
    else:  # gimbal lock: put everything into yaw
        roll = 0.0
        yaw = math.atan2(-rot[0, 1], rot[1, 1])
    return np.array([roll, pitch, yaw])


def matrix_to_quaternion(rot: np.ndarray) -> tuple[float, float, float, float]:
    """Rotation matrix to an (x, y, z, w) quaternion."""
    m = rot
    trace = m[0, 0] + m[1, 1] + m[2, 2]
    if trace > 0:
        s = 2.0 * math.sqrt(trace + 1.0)
        return ((m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s, 0.25 * s)
    i = int(np.argmax([m[0, 0], m[1, 1], m[2, 2]]))
    j, k = (i + 1) % 3, (i + 2) % 3
    s = 2.0 * math.sqrt(max(1.0 + m[i, i] - m[j, j] - m[k, k], 1e-300))
    q = [0.0, 0.0, 0.0, 0.0]
    q[i] = 0.25 * s
    q[j] = (m[j, i] + m[i, j]) / s
    q[k] = (m[k, i] + m[i, k]) / s
    q[3] = (m[k, j] - m[j, k]) / s
    return (q[0], q[1], q[2], q[3])


def quaternion_to_matrix(quat: tuple[float, float, float, float] | np.ndarray) -> np.ndarray:
    x, y, z, w = (float(v) for v in quat)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def rotvec_to_matrix(v: np.ndarray) -> np.ndarray:
    """Rodrigues' formula: a rotation of |v| rad about v."""
    angle = math.sqrt(float(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]))
    if angle < 1e-12:
        return np.eye(3)
    k = v / angle
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(angle) * kx + (1.0 - math.cos(angle)) * (kx @ kx)


def matrix_to_rotvec(rot: np.ndarray) -> np.ndarray:
    """Logarithm of a rotation matrix as a rotation vector (axis * angle), stable near 0 and pi."""
    cos = max(-1.0, min(1.0, (rot[0, 0] + rot[1, 1] + rot[2, 2] - 1.0) / 2.0))
    vee = np.array([rot[2, 1] - rot[1, 2], rot[0, 2] - rot[2, 0], rot[1, 0] - rot[0, 1]])
    if cos > 1.0 - 1e-10:
        return 0.5 * vee
    angle = math.acos(cos)
    if angle < math.pi - 1e-4:
        return (angle / (2.0 * math.sin(angle))) * vee
    # near pi: the symmetric part of R is cos I + (1 - cos) k k^T; take k from its dominant column
    sym = ((rot + rot.T) / 2.0 - cos * np.eye(3)) / (1.0 - cos)
    i = int(np.argmax(np.diag(sym)))
    axis = sym[:, i] / math.sqrt(max(sym[i, i], 1e-300))
    if axis @ vee < 0:
        axis = -axis
    return angle * axis


def pose_matrix(position: np.ndarray | tuple[float, ...], rot: np.ndarray) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = rot
    out[:3, 3] = position
    return out
