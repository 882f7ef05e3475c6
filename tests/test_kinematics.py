"""Forward kinematics over the joint chain (the paper's DH table, or the URDF's joints), Jacobian
and DLS inverse kinematics against independent references: PyBullet's own forward kinematics
and Jacobian, finite differences, and DH and joint matrices built here."""

from __future__ import annotations

import math
import re
from dataclasses import replace

import numpy as np
import pybullet as p
import pytest

from rayreach.robots.chain import urdf_chain
from rayreach.sim.ik_kernel import frames_kernel
from rayreach.sim.kinematics import IKParams, Kinematics
from rayreach.sim.scene import Scene
from rayreach.sim.transforms import matrix_to_rotvec, pose_matrix, quaternion_to_matrix, rpy_to_matrix

# PyBullet accumulates link poses in single precision: its quaternions are off unit length by
# up to ~3e-7, so they are normalised before comparison (errors seen: ~1.3e-7 m, ~7e-7 rad).
POS_TOL = 1e-6
ROT_TOL = 1e-6


def bullet_rotation(quat: np.ndarray) -> np.ndarray:
    quat = np.asarray(quat, dtype=float)
    return quaternion_to_matrix(quat / np.linalg.norm(quat))


def rotation_angle(r_a: np.ndarray, r_b: np.ndarray) -> float:
    return float(np.linalg.norm(matrix_to_rotvec(r_a @ r_b.T)))


# ---------------------------------------------------------------------- forward kinematics
def test_fk_matches_pybullet_tool_tip_and_flange(rig):
    rng = np.random.default_rng(1234)
    scene, kin = rig.scene, rig.kin
    worst = {"tip_pos": 0.0, "tip_rot": 0.0, "flange_pos": 0.0, "flange_rot": 0.0}
    for _ in range(1000):
        q = rig.random_q(rng)
        scene.set_joints(q)
        frames = kin.frames(q)
        tip = kin.fk(q)
        pos, quat = scene.tcp_pose()
        worst["tip_pos"] = max(worst["tip_pos"], float(np.linalg.norm(pos - tip[:3, 3])))
        worst["tip_rot"] = max(worst["tip_rot"], rotation_angle(bullet_rotation(quat), tip[:3, :3]))
        fpos, fquat = scene.link_pose("tool0")
        worst["flange_pos"] = max(worst["flange_pos"], float(np.linalg.norm(fpos - frames[6][:3, 3])))
        worst["flange_rot"] = max(
            worst["flange_rot"], rotation_angle(bullet_rotation(fquat), frames[6][:3, :3])
        )
    assert worst["tip_pos"] < POS_TOL, worst
    assert worst["flange_pos"] < POS_TOL, worst
    assert worst["tip_rot"] < ROT_TOL, worst
    assert worst["flange_rot"] < ROT_TOL, worst


def test_fk_tool_tip_is_tool_length_along_flange_z(rig):
    rng = np.random.default_rng(7)
    for _ in range(20):
        q = rig.random_q(rng)
        flange = rig.kin.frames(q)[-1]
        tip = rig.kin.fk(q)
        expected = flange[:3, 3] + rig.spec.tool.length * flange[:3, 2]
        np.testing.assert_allclose(tip[:3, 3], expected, atol=1e-12)
        np.testing.assert_allclose(tip[:3, :3], flange[:3, :3], atol=1e-12)


@pytest.mark.parametrize("name", ["ur5", "kr16", "ur10"])
def test_fk_with_a_custom_base_pose_matches_pybullet(name, rigs):
    """The base pose is folded into frame 0: a moved and turned base must agree too."""
    spec = rigs[name].spec
    base_pos, base_rpy = (0.3, -0.2, 0.15), (0.1, -0.2, 0.7)
    kin = Kinematics(spec, base_pos, base_rpy)
    scene = Scene(spec, base_pos, base_rpy)
    try:
        rng = np.random.default_rng(99)
        for _ in range(50):
            q = rigs[name].random_q(rng)
            scene.set_joints(q)
            pos, quat = scene.tcp_pose()
            tip = kin.fk(q)
            assert np.linalg.norm(pos - tip[:3, 3]) < POS_TOL
            assert rotation_angle(bullet_rotation(quat), tip[:3, :3]) < ROT_TOL
    finally:
        scene.close()


def _dh_reference(theta: float, d: float, a: float, alpha: float) -> np.ndarray:
    """Rz(theta) Tz(d) Tx(a) Rx(alpha), multiplied out of elementary transforms."""

    def rz(t):
        m = np.eye(4)
        m[:2, :2] = [[math.cos(t), -math.sin(t)], [math.sin(t), math.cos(t)]]
        return m

    def rx(t):
        m = np.eye(4)
        m[1:3, 1:3] = [[math.cos(t), -math.sin(t)], [math.sin(t), math.cos(t)]]
        return m

    def tz(v):
        m = np.eye(4)
        m[2, 3] = v
        return m

    def tx(v):
        m = np.eye(4)
        m[0, 3] = v
        return m

    return rz(theta) @ tz(d) @ tx(a) @ rx(alpha)


@pytest.mark.parametrize("name", ["ur5", "kr16"])
def test_frames_chain_paper_eq2_dh_matrices_from_the_world_base(name, rigs):
    """Paper eq. 1: frame i = frame 0 @ prod_{k<=i} T_k (eq. 2, built here), frame 0 = base pose @
    DH base rotation: the chain form of the DH table is the paper's kinematics."""
    rig = rigs[name]
    dh = rig.spec.dh
    rng = np.random.default_rng(5)
    base = np.eye(4)
    base[:3, :3] = rpy_to_matrix(rig.spec.base_rpy) @ rpy_to_matrix(rig.spec.dh_base_rpy)
    base[:3, 3] = rig.spec.base_position
    for _ in range(20):
        q = rig.random_q(rng)
        frames = rig.kin.frames(q)
        np.testing.assert_allclose(frames[0], base, atol=1e-12)
        acc = base
        for i in range(6):
            acc = acc @ _dh_reference(dh.sign[i] * q[i] + dh.offset[i], dh.d[i], dh.a[i], dh.alpha[i])
            np.testing.assert_allclose(frames[i + 1], acc, atol=1e-12, err_msg=f"joint {i}")


@pytest.mark.parametrize("name", ["ur5", "kr16"])
def test_urdf_chain_agrees_with_the_dh_table(name, rigs):
    """The paper's two robots read from their URDF's joints, without the DH table, place the
    flange and the tool tip where the DH chain does, and have the same Jacobian there."""
    dh_kin = rigs[name].kin
    urdf_kin = Kinematics(replace(rigs[name].spec, dh=None))
    assert urdf_kin.chain.key() != dh_kin.chain.key()  # two different chains, one arm
    rng = np.random.default_rng(11)
    for _ in range(1000):
        q = rigs[name].random_q(rng)
        a, b = dh_kin.frames(q), urdf_kin.frames(q)
        np.testing.assert_allclose(b[-1], a[-1], atol=1e-9)
        np.testing.assert_allclose(urdf_kin.fk(q), dh_kin.fk(q), atol=1e-9)
    np.testing.assert_allclose(urdf_kin.jacobian(b), dh_kin.jacobian(a), atol=1e-9)


URDF_TWO_JOINTS = """<robot name="two">
  <link name="base"/><link name="upper"/><link name="tip"/><link name="flange"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="upper"/>
    <origin xyz="0 0 0.5" rpy="0 0 0"/><axis xyz="0 0 1"/></joint>
  <joint name="j2" type="{kind}"><parent link="upper"/><child link="tip"/>
    <origin xyz="0.3 0 0" rpy="0 1.5707963267948966 0"/><axis xyz="0 1 0"/></joint>
  <joint name="j3" type="fixed"><parent link="tip"/><child link="flange"/><origin xyz="0 0 0.2"/></joint>
  <transmission name="t1"><joint name="j1"/></transmission>
</robot>"""


def test_urdf_chain_of_a_small_arm_by_hand():
    """Two joints and a fixed flange, composed here by hand: origin, then the turn about the axis."""
    chain = urdf_chain(URDF_TWO_JOINTS.format(kind="revolute"), ("j1", "j2"), "flange")
    assert chain.n_joints == 2
    np.testing.assert_allclose(chain.axis, [[0, 0, 1], [0, 1, 0]])
    q = np.array([0.4, -0.7])
    expected = (pose_matrix((0, 0, 0.5), rpy_to_matrix((0, 0, q[0])))
                @ pose_matrix((0.3, 0, 0), rpy_to_matrix((0, math.pi / 2, 0)) @ rpy_to_matrix((0, q[1], 0)))
                @ pose_matrix((0, 0, 0.2), np.eye(3)))
    out = np.empty((3, 4, 4))
    frames_kernel(np.eye(4), chain.before, chain.axis, chain.after, q, out)
    np.testing.assert_allclose(out[-1], expected, atol=1e-12)


def test_urdf_chain_starts_at_its_base_link_through_the_fixed_joints_above():
    mounted = URDF_TWO_JOINTS.format(kind="revolute").replace(
        '<link name="base"/>', '<link name="world"/><link name="base"/><joint name="mount" type="fixed">'
        '<parent link="world"/><child link="base"/><origin xyz="0 0 0.1" rpy="0 0 0.3"/></joint>')
    chain = urdf_chain(mounted, ("j1", "j2"), "flange", base_link="base")
    np.testing.assert_allclose(chain.root, pose_matrix((0, 0, 0.1), rpy_to_matrix((0, 0, 0.3))), atol=1e-12)
    plain = urdf_chain(URDF_TWO_JOINTS.format(kind="revolute"), ("j1", "j2"), "flange")
    np.testing.assert_allclose(chain.before, plain.before, atol=1e-12)
    with pytest.raises(ValueError, match="joint 'j1' \\(revolute\\) lies between the URDF's root 'world'"):
        urdf_chain(mounted, ("j2",), "flange", base_link="upper")
    with pytest.raises(ValueError, match="link 'elsewhere' is not on the way from the URDF's root 'world'"):
        urdf_chain(mounted, ("j1", "j2"), "flange", base_link="elsewhere")


@pytest.mark.parametrize("names, tip, kind, message", [
    (("j1", "j2"), "nowhere", "revolute", "URDF has no link 'nowhere'; links: base, flange, tip, upper"),
    (("j2", "j1"), "flange", "revolute", "moving joints from 'base' to 'flange' are ('j1', 'j2')"),
    (("j1", "j2"), "flange", "prismatic", "joint 'j2' is prismatic; a chain takes revolute, continuous or fixed"),
])
def test_urdf_chain_refuses_what_it_cannot_read(names, tip, kind, message):
    with pytest.raises(ValueError, match=re.escape(message)):
        urdf_chain(URDF_TWO_JOINTS.format(kind=kind), names, tip)


# ---------------------------------------------------------------------- Jacobian
def test_jacobian_matches_finite_differences_of_fk(rig):
    rng = np.random.default_rng(11)
    kin = rig.kin
    h = 1e-6
    for _ in range(8):
        q = rig.random_q(rng)
        jac = kin.jacobian(kin.frames(q))
        assert jac.shape == (6, 6)
        num = np.empty((6, 6))
        for i in range(6):
            step = np.zeros(6)
            step[i] = h
            plus, minus = kin.fk(q + step), kin.fk(q - step)
            num[:3, i] = (plus[:3, 3] - minus[:3, 3]) / (2 * h)
            num[3:, i] = matrix_to_rotvec(plus[:3, :3] @ minus[:3, :3].T) / (2 * h)
        np.testing.assert_allclose(jac, num, atol=1e-7)


def test_jacobian_of_another_point(rig):
    """``point`` is honoured: the flange's linear velocity is d(flange position)/dq."""
    kin = rig.kin
    q = rig.random_q(np.random.default_rng(12))
    frames = kin.frames(q)
    jac = kin.jacobian(frames, point=frames[-1][:3, 3])
    h = 1e-6
    for i in range(6):
        step = np.zeros(6)
        step[i] = h
        num = (kin.frames(q + step)[-1][:3, 3] - kin.frames(q - step)[-1][:3, 3]) / (2 * h)
        np.testing.assert_allclose(jac[:3, i], num, atol=1e-7)


def test_jacobian_matches_pybullet_calculate_jacobian(rig):
    """PyBullet expresses its Jacobian in the base frame; rotated into the world it must match."""
    scene, kin = rig.scene, rig.kin
    base_rot = rpy_to_matrix(rig.spec.base_rpy)
    rng = np.random.default_rng(13)
    for _ in range(10):
        q = rig.random_q(rng)
        scene.set_joints(q)
        lin, ang = p.calculateJacobian(
            scene.robot,
            scene.tcp_link,
            [0.0, 0.0, 0.0],
            list(map(float, q)),
            [0.0] * 6,
            [0.0] * 6,
            physicsClientId=scene.client,
        )
        jac = kin.jacobian(kin.frames(q))
        np.testing.assert_allclose(base_rot @ np.array(lin), jac[:3], atol=1e-9)
        np.testing.assert_allclose(base_rot @ np.array(ang), jac[3:], atol=1e-9)


# ---------------------------------------------------------------------- inverse kinematics
def _smallest_singular_value(kin: Kinematics, q: np.ndarray) -> float:
    return float(np.linalg.svd(kin.jacobian(kin.frames(q)), compute_uv=False)[-1])


WELL_CONDITIONED = 0.02
"""sigma_min(J) above which a target counts as away from singularities. DLS with a constant
lambda = 0.05 contracts the error along a singular direction by lambda^2 / (sigma^2 + lambda^2)
per iteration, so 100 iterations could not reach 1e-5 where sigma_min is much below this; the
error-scaled damping (IKParams.damping_scale) is what makes near-singular targets converge."""


def _ik_round_trip(rig, n: int, seed: int):
    """Returns, per sample: converged-and-accurate, sigma_min at the target, and whether a
    converged answer is genuinely at the target (checked with an independent fk)."""
    kin = rig.kin
    rng = np.random.default_rng(seed)
    ok = np.zeros(n, dtype=bool)
    sigma = np.zeros(n)
    for k in range(n):
        q = rig.random_q(rng, clip_pi=True)
        target = kin.fk(q)
        start = np.clip(q + rng.uniform(-0.2, 0.2, 6), kin.lower, kin.upper)
        result = kin.ik(target[:3, 3], target[:3, :3], start, IKParams())
        assert np.all(result.q >= kin.lower) and np.all(result.q <= kin.upper)
        reached = kin.fk(result.q)
        pos_err = float(np.linalg.norm(reached[:3, 3] - target[:3, 3]))
        rot_err = rotation_angle(target[:3, :3], reached[:3, :3])
        # the reported errors are the real ones
        assert result.position_error == pytest.approx(pos_err, abs=1e-12)
        assert result.orientation_error == pytest.approx(rot_err, abs=1e-9)
        np.testing.assert_allclose(result.frames, kin.frames(result.q), atol=1e-12)
        if result.converged:  # never a silent wrong answer
            assert math.hypot(pos_err, rot_err) <= IKParams().tolerance + 1e-12
        ok[k] = result.converged and result.position_error < 1e-4
        sigma[k] = _smallest_singular_value(kin, q)
    return ok, sigma


def _check_round_trip(rig, n: int, seed: int, min_rate: float) -> None:
    ok, sigma = _ik_round_trip(rig, n, seed)
    good = sigma > WELL_CONDITIONED
    rate_good = ok[good].mean()
    assert good.sum() >= 0.5 * n
    assert rate_good >= min_rate, f"{rig.name}: {rate_good:.3f} of {good.sum()} well-conditioned targets"
    assert ok.mean() >= min_rate, f"{rig.name}: {ok.mean():.3f} of all {n} targets"


def test_ik_round_trip_full_pose(rig):
    """1,000 random poses, seeds within +-0.2 rad per joint (about 1.5 s per robot)."""
    _check_round_trip(rig, 1000, seed=21, min_rate=0.99)


def test_ik_unreachable_target_reports_failure(rig):
    kin = rig.kin
    base = np.asarray(rig.spec.base_position)
    rng = np.random.default_rng(31)
    chain = rig.kin.chain  # bound on |tip - base|: every link's offset laid end to end
    reach = (np.linalg.norm(chain.before[:, :3, 3], axis=1).sum() + np.linalg.norm(chain.after[:, :3, 3], axis=1).sum()
             + rig.spec.tool.length)
    for direction in ([1.0, 0.0, 0.0], [0.0, -1.0, 0.3], [0.3, 0.4, 1.0]):
        d = np.asarray(direction) / np.linalg.norm(direction)
        target = base + 3.0 * d
        start = rig.random_q(rng)
        result = kin.ik(target, None, start, IKParams())
        assert not result.converged
        assert result.position_error >= 3.0 - reach - 1e-9 > 0.3
        assert result.position_error == pytest.approx(np.linalg.norm(kin.fk(result.q)[:3, 3] - target))
        assert np.all(result.q >= kin.lower) and np.all(result.q <= kin.upper)
        result6 = kin.ik(target, np.eye(3), start, IKParams())
        assert not result6.converged and result6.position_error >= 3.0 - reach - 1e-9
        assert np.all(result6.q >= kin.lower) and np.all(result6.q <= kin.upper)


def test_ik_clips_to_joint_limits_even_from_outside(rig):
    kin = rig.kin
    start = kin.upper + 1.0  # seed outside every limit
    target = kin.fk(rig.spec.home)
    result = kin.ik(target[:3, 3], target[:3, :3], start, IKParams(max_iterations=5))
    assert np.all(result.q >= kin.lower) and np.all(result.q <= kin.upper)


def test_ik_position_only_converges(rig):
    kin = rig.kin
    rng = np.random.default_rng(41)
    n, ok = 200, 0
    for _ in range(n):
        q = rig.random_q(rng, clip_pi=True)
        target = kin.fk(q)[:3, 3]
        start = np.clip(q + rng.uniform(-0.2, 0.2, 6), kin.lower, kin.upper)
        result = kin.ik(target, None, start, IKParams())
        assert result.orientation_error == 0.0
        err = float(np.linalg.norm(kin.fk(result.q)[:3, 3] - target))
        assert result.position_error == pytest.approx(err, abs=1e-12)
        if result.converged:
            assert err <= IKParams().tolerance
            ok += 1
    assert ok >= 0.99 * n, f"{rig.name}: position-only IK converged in {ok}/{n}"


def test_ik_moves_towards_the_target_not_away():
    """Paper Algorithm 1 writes x_e = x_c - x_d; the update must use x_d - x_c. One step
    from a nearby seed must reduce the error."""
    from rayreach.robots import get_robot

    kin = Kinematics(get_robot("ur5"))
    q = np.asarray(kin.spec.home)
    target = kin.fk(q + 0.05)
    before = np.linalg.norm(kin.fk(q)[:3, 3] - target[:3, 3])
    result = kin.ik(target[:3, 3], target[:3, :3], q, IKParams(max_iterations=1))
    assert result.iterations == 1
    assert result.position_error < 0.5 * before


@pytest.mark.parametrize("scale", [None, 0.05])
def test_ik_iteration_is_algorithm_1_update(scale):
    """One iteration equals q + dint * J^T (J J^T + lambda^2 I)^-1 (x_d - x_c) / ddif, with the
    paper's constant lambda (scale None) or lambda^2 * ||x_e|| / scale below the scale."""
    from rayreach.robots import get_robot
    from rayreach.sim.transforms import matrix_to_rotvec

    kin = Kinematics(get_robot("kr16"))
    q = np.asarray(kin.spec.home)
    target = kin.fk(q + 0.01)
    params = IKParams(damping=0.05, delta_int=0.02, delta_dif=0.01, damping_scale=scale, max_iterations=1)
    current = kin.fk(q)
    error = np.concatenate((target[:3, 3] - current[:3, 3], matrix_to_rotvec(target[:3, :3] @ current[:3, :3].T)))
    lam2 = 0.05**2 if scale is None else 0.05**2 * np.linalg.norm(error) / scale
    assert np.linalg.norm(error) < 0.05  # the scaled branch is the one exercised
    jac = kin.jacobian(kin.frames(q))
    expected = q + 0.02 * jac.T @ np.linalg.solve(jac @ jac.T + lam2 * np.eye(6), error / 0.01)
    result = kin.ik(target[:3, 3], target[:3, :3], q, params)
    np.testing.assert_allclose(result.q, expected, atol=1e-12)
