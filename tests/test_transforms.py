"""Rotation helpers against PyBullet's conventions and against each other."""

from __future__ import annotations

import math

import numpy as np
import pybullet as p
import pytest

from rayreach.sim.transforms import (
    matrix_to_quaternion,
    matrix_to_rotvec,
    matrix_to_rpy,
    pose_matrix,
    quaternion_to_matrix,
    rotvec_to_matrix,
    rpy_to_matrix,
)

RNG_SEED = 2024


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    quat = rng.normal(size=4)
    return quaternion_to_matrix(quat / np.linalg.norm(quat))


def random_unit(rng: np.random.Generator) -> np.ndarray:
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def is_rotation(m: np.ndarray) -> bool:
    return np.allclose(m @ m.T, np.eye(3), atol=1e-12) and abs(np.linalg.det(m) - 1.0) < 1e-12


def test_rpy_to_matrix_matches_pybullet():
    rng = np.random.default_rng(RNG_SEED)
    for _ in range(300):
        rpy = rng.uniform(-math.pi, math.pi, 3)
        ref = np.array(p.getMatrixFromQuaternion(p.getQuaternionFromEuler(rpy.tolist()))).reshape(3, 3)
        np.testing.assert_allclose(rpy_to_matrix(rpy), ref, atol=1e-12)


def test_rpy_to_matrix_is_extrinsic_xyz():
    r, pi_, y = 0.3, -0.7, 1.9
    rx = np.array([[1, 0, 0], [0, math.cos(r), -math.sin(r)], [0, math.sin(r), math.cos(r)]])
    ry = np.array([[math.cos(pi_), 0, math.sin(pi_)], [0, 1, 0], [-math.sin(pi_), 0, math.cos(pi_)]])
    rz = np.array([[math.cos(y), -math.sin(y), 0], [math.sin(y), math.cos(y), 0], [0, 0, 1]])
    np.testing.assert_allclose(rpy_to_matrix((r, pi_, y)), rz @ ry @ rx, atol=1e-15)


def test_matrix_to_rpy_inverts_rpy_to_matrix():
    rng = np.random.default_rng(RNG_SEED + 1)
    for _ in range(500):
        rpy = np.array(
            [rng.uniform(-math.pi, math.pi), rng.uniform(-1.5, 1.5), rng.uniform(-math.pi, math.pi)]
        )
        np.testing.assert_allclose(matrix_to_rpy(rpy_to_matrix(rpy)), rpy, atol=1e-10)


def test_matrix_to_rpy_matches_pybullet_euler():
    rng = np.random.default_rng(RNG_SEED + 2)
    for _ in range(200):
        rot = random_rotation(rng)
        ours = matrix_to_rpy(rot)
        ref = p.getEulerFromQuaternion(matrix_to_quaternion(rot))
        np.testing.assert_allclose(rpy_to_matrix(ours), rot, atol=1e-10)
        # PyBullet works in single precision here
        np.testing.assert_allclose(rpy_to_matrix(ref), rot, atol=1e-6)
        assert -math.pi / 2 <= ours[1] <= math.pi / 2


@pytest.mark.parametrize("pitch", [math.pi / 2, -math.pi / 2])
def test_matrix_to_rpy_gimbal_lock_reproduces_the_rotation(pitch):
    for roll, yaw in [(0.3, 1.2), (-2.0, 0.5), (3.0, -3.0)]:
        rot = rpy_to_matrix((roll, pitch, yaw))
        rpy = matrix_to_rpy(rot)
        assert rpy[1] == pytest.approx(pitch)
        np.testing.assert_allclose(rpy_to_matrix(rpy), rot, atol=1e-9)


def test_quaternion_to_matrix_matches_pybullet():
    rng = np.random.default_rng(RNG_SEED + 3)
    for _ in range(200):
        quat = rng.normal(size=4)
        quat /= np.linalg.norm(quat)
        ref = np.array(p.getMatrixFromQuaternion(quat.tolist())).reshape(3, 3)
        ours = quaternion_to_matrix(quat)
        assert is_rotation(ours)
        np.testing.assert_allclose(ours, ref, atol=1e-12)


def test_quaternion_round_trips_all_branches():
    rng = np.random.default_rng(RNG_SEED + 4)
    rots = [random_rotation(rng) for _ in range(300)]
    # rotations by pi about x, y, z and near-pi ones: trace <= 0, every argmax branch
    for axis in np.eye(3):
        rots.append(rotvec_to_matrix(math.pi * axis))
        rots.append(rotvec_to_matrix((math.pi - 1e-3) * axis))
        rots.append(rotvec_to_matrix(2.5 * axis))
    rots.append(np.eye(3))
    branches = set()
    for rot in rots:
        quat = np.array(matrix_to_quaternion(rot))
        assert np.linalg.norm(quat) == pytest.approx(1.0, abs=1e-12)
        np.testing.assert_allclose(quaternion_to_matrix(quat), rot, atol=1e-12)
        trace = np.trace(rot)
        branches.add("trace" if trace > 0 else int(np.argmax(np.diag(rot))))
        # quaternion -> matrix -> quaternion gives the same quaternion up to sign
        back = np.array(matrix_to_quaternion(quaternion_to_matrix(quat)))
        assert min(np.abs(back - quat).max(), np.abs(back + quat).max()) < 1e-12
    assert branches == {"trace", 0, 1, 2}


def test_matrix_to_quaternion_matches_pybullet():
    rng = np.random.default_rng(RNG_SEED + 5)
    for _ in range(100):
        rpy = rng.uniform(-math.pi, math.pi, 3)
        ref = np.array(p.getQuaternionFromEuler(rpy.tolist()))
        ours = np.array(matrix_to_quaternion(rpy_to_matrix(rpy)))
        assert min(np.abs(ours - ref).max(), np.abs(ours + ref).max()) < 1e-6


def test_rotvec_to_matrix_rodrigues():
    rng = np.random.default_rng(RNG_SEED + 6)
    for _ in range(100):
        axis = random_unit(rng)
        angle = rng.uniform(0, math.pi)
        rot = rotvec_to_matrix(angle * axis)
        assert is_rotation(rot)
        np.testing.assert_allclose(rot @ axis, axis, atol=1e-12)  # the axis is fixed
        assert np.trace(rot) == pytest.approx(1 + 2 * math.cos(angle), abs=1e-12)
        # same rotation as the quaternion (axis sin(angle/2), cos(angle/2))
        quat = np.append(axis * math.sin(angle / 2), math.cos(angle / 2))
        np.testing.assert_allclose(rot, quaternion_to_matrix(quat), atol=1e-12)


def test_rotvec_round_trip_generic_angles():
    rng = np.random.default_rng(RNG_SEED + 7)
    for _ in range(500):
        v = random_unit(rng) * rng.uniform(1e-3, math.pi - 1e-3)
        np.testing.assert_allclose(matrix_to_rotvec(rotvec_to_matrix(v)), v, atol=1e-10)


@pytest.mark.parametrize("angle", [0.0, 1e-13, 1e-10, 1e-8, 1e-6, 1e-4])
def test_rotvec_round_trip_near_zero(angle):
    rng = np.random.default_rng(RNG_SEED + 8)
    for _ in range(50):
        v = random_unit(rng) * angle
        np.testing.assert_allclose(
            matrix_to_rotvec(rotvec_to_matrix(v)), v, atol=1e-12 + 1e-9 * angle
        )  # below 1e-12 rad, identity
    assert np.array_equal(matrix_to_rotvec(np.eye(3)), np.zeros(3))


def test_rotvec_at_exactly_pi():
    rng = np.random.default_rng(RNG_SEED + 9)
    for _ in range(200):
        axis = random_unit(rng)
        v = matrix_to_rotvec(rotvec_to_matrix(math.pi * axis))
        assert np.linalg.norm(v) == pytest.approx(math.pi, abs=1e-7)
        # axis up to sign (a rotation by pi about k equals one about -k)
        assert min(np.linalg.norm(v - math.pi * axis), np.linalg.norm(v + math.pi * axis)) < 1e-6
        np.testing.assert_allclose(rotvec_to_matrix(v), rotvec_to_matrix(math.pi * axis), atol=1e-7)


@pytest.mark.parametrize("gap", [1e-7, 1e-6, 1e-5, 5e-5, 9.9e-5, 1.01e-4, 1e-3])
def test_rotvec_round_trip_near_pi(gap):
    """Angles pi - gap: the branch for angles within 1e-4 of pi must be as accurate as the
    generic one just outside it (the acos is ill-conditioned here, ~1e-16 / gap)."""
    rng = np.random.default_rng(RNG_SEED + 10)
    worst = 0.0
    for _ in range(200):
        v = random_unit(rng) * (math.pi - gap)
        worst = max(worst, float(np.linalg.norm(matrix_to_rotvec(rotvec_to_matrix(v)) - v)))
    assert worst < 1e-6, f"rotvec error {worst:.3g} rad at angle pi - {gap:g}"


def test_matrix_to_rotvec_is_the_inverse_on_random_rotations():
    rng = np.random.default_rng(RNG_SEED + 11)
    for _ in range(500):
        rot = random_rotation(rng)
        v = matrix_to_rotvec(rot)
        assert np.linalg.norm(v) <= math.pi + 1e-12
        np.testing.assert_allclose(rotvec_to_matrix(v), rot, atol=1e-9)


def test_pose_matrix():
    rot = rpy_to_matrix((0.1, 0.2, 0.3))
    m = pose_matrix((1.0, 2.0, 3.0), rot)
    np.testing.assert_array_equal(m[:3, :3], rot)
    np.testing.assert_array_equal(m[:3, 3], [1.0, 2.0, 3.0])
    np.testing.assert_array_equal(m[3], [0, 0, 0, 1])
