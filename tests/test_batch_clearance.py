"""The teacher's privileged values against PyBullet: each arm sphere's gap to the nearest
obstacle is ``getClosestPoints``' distance between a ball there and the obstacles, the
encoded direction points where PyBullet's closest point lies, and a back-and-forth
obstacle's motion turns with it."""

from __future__ import annotations

import numpy as np
import pybullet as p
import pytest

from rayreach.robots import get_robot
from rayreach.scenarios.schema import ObstacleSpec
from rayreach.sim.batch_clearance import PER_SPHERE, REACH, SPEED_SCALE, clearance, gaps
from rayreach.sim.batch_collision import CollisionWorlds, _place
from rayreach.sim.batch_obstacles import ObstacleBatch
from rayreach.sim.kinematics import Kinematics


@pytest.fixture(scope="module")
def arm():
    spec = get_robot("ur5")
    worlds = CollisionWorlds(spec, 1)
    yield Kinematics(spec), worlds.spheres
    worlds.close()


def _scene(kin, q, rng):
    """Obstacles near the arm's tool at ``q``: a rotated box and a ball."""
    ee = kin.ee_from_frames(kin.frames(q))[:3, 3]
    return [
        ObstacleSpec(shape="box", position=tuple(ee + rng.uniform(-0.15, 0.15, 3)),
                     rpy=tuple(rng.uniform(-1, 1, 3)), half_extents=tuple(rng.uniform(0.005, 0.1, 3))),
        ObstacleSpec(shape="sphere", position=tuple(ee + rng.uniform(-0.2, 0.2, 3)), radius=float(rng.uniform(0.02, 0.08))),
    ]


def _pybullet_nearest(obstacles, centre, radius):
    """PyBullet's distance from a ball at ``centre`` to the nearest obstacle, and the point on it."""
    cid = p.connect(p.DIRECT)
    try:
        ball = p.createMultiBody(0, p.createCollisionShape(p.GEOM_SPHERE, radius=radius, physicsClientId=cid),
                                 basePosition=list(centre), physicsClientId=cid)
        best = (np.inf, None)
        for o in obstacles:
            shape = (p.createCollisionShape(p.GEOM_BOX, halfExtents=list(o.half_extents), physicsClientId=cid)
                     if o.shape == "box" else
                     p.createCollisionShape(p.GEOM_SPHERE, radius=o.radius, physicsClientId=cid))
            body = p.createMultiBody(0, shape, basePosition=list(o.position),
                                     baseOrientation=p.getQuaternionFromEuler(o.rpy), physicsClientId=cid)
            points = p.getClosestPoints(ball, body, 2.0, physicsClientId=cid)
            if points and points[0][8] < best[0]:
                best = (points[0][8], np.asarray(points[0][6]))
        return best
    finally:
        p.disconnect(cid)


def test_gaps_and_directions_are_pybullets(arm):
    kin, spheres = arm
    rng = np.random.default_rng(3)
    checked = 0
    for _ in range(4):
        q = rng.uniform(kin.lower, kin.upper)
        obstacles = _scene(kin, q, rng)
        batch = ObstacleBatch(1)
        batch.set_world(0, obstacles)
        frames = kin.frames(q)[None]
        ours = gaps(frames, spheres, batch)[0]
        values = np.zeros((1, PER_SPHERE * len(spheres.frame)))
        ee_rot = kin.ee_from_frames(frames[0])[:3, :3]
        clearance(frames, spheres, batch, np.zeros(1), ee_rot[None], np.array([0]), values)
        centres = np.empty((len(spheres.frame), 3))
        _place(frames[0], spheres.frame, spheres.centre, centres)
        for k in range(0, len(spheres.frame), 3):
            distance, on_obstacle = _pybullet_nearest(obstacles, centres[k], float(spheres.radius[k]))
            if distance <= 0:
                continue  # overlapping: PyBullet's point is a penetration's, ours the sphere's centre
            assert ours[k] == pytest.approx(distance, abs=2e-3)
            near = values[0, k * PER_SPHERE: k * PER_SPHERE + 3]
            if distance < REACH:
                offset = on_obstacle - centres[k]
                tolerance = 0.01 + 0.004 / np.linalg.norm(offset)  # PyBullet's point is good to a few mm
                assert ee_rot @ near / np.linalg.norm(near) == pytest.approx(offset / np.linalg.norm(offset),
                                                                             abs=tolerance)
                assert np.linalg.norm(near) == pytest.approx(1 - distance / REACH, abs=1e-2)
                checked += 1
            else:
                assert not near.any()
    assert checked >= 10


def test_nothing_near_reads_zero_and_motion_turns_with_the_obstacle(arm):
    kin, spheres = arm
    q = np.asarray(kin.spec.home)
    frames = kin.frames(q)[None]
    ee = kin.ee_from_frames(frames[0])
    far = ObstacleSpec(shape="box", position=tuple(ee[:3, 3] + [3.0, 0, 0]), half_extents=(0.05, 0.05, 0.05))
    batch = ObstacleBatch(1)
    batch.set_world(0, [far])
    values = np.ones((1, PER_SPHERE * len(spheres.frame)))
    clearance(frames, spheres, batch, np.zeros(1), ee[None, :3, :3], np.array([0]), values)
    assert not values.any()

    velocity = np.array([0.0, 0.1, 0.0])
    plate = ObstacleSpec(shape="box", position=tuple(ee[:3, 3] + [0, 0, 0.05]), half_extents=(0.1, 0.1, 0.002),
                         velocity=tuple(velocity), travel=0.2)
    batch.set_world(0, [plate])
    motion = {}
    for t in (0.5, 2.5):  # out at 0.1 m/s for 2 s, then back
        clearance(frames, spheres, batch, np.array([t]), ee[None, :3, :3], np.array([0]), values)
        rows = values[0].reshape(-1, PER_SPHERE)
        seen = np.abs(rows[:, :3]).sum(axis=1) > 0
        assert seen.any()
        motion[t] = ee[:3, :3] @ rows[seen][0, 3:] * SPEED_SCALE
    assert motion[0.5] == pytest.approx(velocity, abs=1e-9)
    assert motion[2.5] == pytest.approx(-velocity, abs=1e-9)
