"""The batched collision test against PyBullet's own: ``candidates`` flags every contact
``Scene.in_collision`` reports, and ``CollisionWorlds.in_collision`` is ``Scene.in_collision``,
on 10,000 configurations per robot near the obstacles of random worlds."""

from __future__ import annotations

import math

import numpy as np
import pybullet as p
import pytest

from rayreach.robots import get_robot
from rayreach.scenarios.schema import ObstacleSpec
from rayreach.sim import batch_collision
from rayreach.sim.batch_collision import (
    ArmSpheres,
    CollisionWorlds,
    _chain,
    _collision_links,
    _link_poses,
    candidates,
    flag_sample,
    link_points,
    near_sample,
)
from rayreach.sim.batch_obstacles import ObstacleBatch
from rayreach.sim.kinematics import Kinematics
from rayreach.sim.scene import Scene

N_CONFIGS = 10_000


@pytest.fixture(scope="module", params=["ur5", "kr16"])
def sample(request):
    """``measure_false_alarms``' own sample, so the figures printed here are the ones it gives."""
    return near_sample(request.param, N_CONFIGS, seed=0)


def test_the_sample_is_near_obstacles_and_often_in_contact(sample):
    assert len(sample.q) == N_CONFIGS
    assert sample.contact.mean() >= 0.2
    assert (~sample.contact).mean() >= 0.2  # near misses too, or false alarms would mean nothing
    assert len(sample.worlds) >= 50
    moving = any(o.moving for world in sample.worlds for o in world)
    assert moving == ("moving_plate" in get_robot(sample.robot).training_kinds)  # the UR5's worlds move


def test_candidates_flag_every_contact_pybullet_reports(sample):
    flagged = flag_sample(sample)
    assert not (sample.contact & ~flagged).any()
    false = flagged & ~sample.contact
    print(f"\n{sample.robot}: {sample.contact.mean():.1%} in contact, {flagged.mean():.1%} flagged; "
          f"false alarms {false.sum() / flagged.sum():.1%} of flagged, {false.mean():.1%} of all")
    assert false.sum() / flagged.sum() < 0.3


def test_without_the_margin_some_contacts_would_be_missed(sample):
    """PyBullet's contacts reach past the meshes (its 1 mm pad): spheres shrunk by a
    millimetre miss some, so the spheres are tight enough for the test above to fail."""
    assert (sample.contact & ~flag_sample(sample, margin=-0.001)).any()
    assert not (sample.contact & ~flag_sample(sample, margin=0.001)).any()


def test_collision_worlds_answer_as_scene_in_collision(sample):
    worlds = CollisionWorlds(get_robot(sample.robot), len(sample.worlds))
    try:
        for i, obstacles in enumerate(sample.worlds):
            worlds.set_world(i, obstacles)
        kin = Kinematics(get_robot(sample.robot))
        order = np.random.default_rng(0).permutation(len(sample.q))  # worlds interleaved, as a batch asks
        every, near = [], []
        for i in order:
            w, q, t = int(sample.world[i]), sample.q[i], float(sample.time[i])
            every.append(worlds.in_collision(w, q, t))
            near.append(worlds.in_collision(w, q, t, kin.frames(q)))
        assert np.array_equal(every, sample.contact[order])
        assert np.array_equal(near, sample.contact[order])
    finally:
        worlds.close()


@pytest.mark.parametrize("robot", ["ur5", "kr16"])
def test_a_margin_counts_what_comes_nearer_than_it_as_a_collision(robot):
    """A ball a few millimetres from the tool: no contact, but within a margin larger than
    its distance (PyBullet's ``getClosestPoints``, through ``Scene.clearance``) it is hit, in
    the scene and in the batched worlds, with and without the broad phase."""
    spec = get_robot(robot)
    q = np.asarray(spec.home)
    kin = Kinematics(spec)
    ee = kin.fk(q)
    box = ObstacleSpec("sphere", tuple(ee[:3, 3] + 0.06 * ee[:3, 2]), radius=0.05)  # ahead of the tool's tip
    scene = Scene(spec)
    worlds = CollisionWorlds(spec, 1)
    try:
        scene.set_obstacles([box])
        scene.set_joints(q)
        worlds.set_world(0, [box])
        gap = scene.clearance(0.1)
        assert 0.002 < gap < 0.05
        for margin in (0.0, gap - 0.001, gap + 0.001, 0.05):
            hit = margin > gap
            assert scene.in_collision(margin) == hit, margin
            assert worlds.in_collision(0, q, 0.0, margin=margin) == hit, margin
            assert worlds.in_collision(0, q, 0.0, kin.frames(q), margin) == hit, margin
    finally:
        scene.close()
        worlds.close()


def test_set_world_replaces_a_worlds_obstacles_and_moves_them_in_time(monkeypatch):
    spec = get_robot("ur5")
    monkeypatch.setattr(batch_collision, "SHAPES_PER_CLIENT", 3)  # a fresh client every few worlds
    worlds = CollisionWorlds(spec, 2)
    try:
        q = np.asarray(spec.home)
        tip = Kinematics(spec).fk(q)[:3, 3]
        block = ObstacleSpec("box", tuple(tip), half_extents=(0.05, 0.05, 0.05))
        worlds.set_world(0, [block])
        assert worlds.in_collision(0, q, 0.0) and not worlds.in_collision(1, q, 0.0)
        first = worlds._scene
        worlds.set_world(0, [])
        worlds.set_world(1, [block])
        assert not worlds.in_collision(0, q, 0.0) and worlds.in_collision(1, q, 0.0)
        away = ObstacleSpec("box", tuple(tip + [0.3, 0.0, 0.0]), half_extents=(0.05, 0.05, 0.05),
                            velocity=(-0.1, 0.0, 0.0), travel=0.3)
        worlds.set_world(1, [away, block])
        worlds.set_world(0, [away])
        assert worlds._scene is not first
        assert [worlds.in_collision(0, q, t) for t in (0.0, 3.0, 6.0)] == [False, True, False]
        assert worlds.in_collision(1, q, 0.0)
        with pytest.raises(ValueError, match="cylinder"):
            worlds.set_world(0, [ObstacleSpec("cylinder", tuple(tip), radius=0.05, height=0.1)])
    finally:
        worlds.close()


@pytest.mark.parametrize("robot", ["ur5", "kr16"])
def test_arm_spheres_hold_every_vertex_where_pybullet_puts_it(robot):
    spec = get_robot(robot)
    kin, scene = Kinematics(spec), Scene(spec)
    try:
        spheres = ArmSpheres.of(scene, kin)
        links = _collision_links(scene)
        assert spheres.links.tolist() == links
        rng = np.random.default_rng(3)
        for _ in range(20):
            q = rng.uniform(kin.lower, kin.upper)
            scene.set_joints(q)
            centres = spheres.world(kin.frames(q))
            for j, (link, pose) in enumerate(zip(links, _link_poses(scene, links))):
                points = link_points(scene, link) @ pose[:3, :3].T + pose[:3, 3]
                mine = slice(spheres.start[j], spheres.start[j + 1])
                gap = np.linalg.norm(points[:, None] - centres[mine][None], axis=2) - spheres.radius[mine]
                assert gap.min(axis=1).max() <= 1e-9
        for j in range(len(links)):  # each link's bound holds its spheres
            mine = slice(spheres.start[j], spheres.start[j + 1])
            assert (spheres.frame[mine] == spheres.bound_frame[j]).all()
            reach = np.linalg.norm(spheres.centre[mine] - spheres.bound_centre[j], axis=1)
            assert (reach + spheres.radius[mine]).max() <= spheres.bound_radius[j] + 1e-12
    finally:
        scene.close()


@pytest.mark.parametrize("robot", ["ur5", "kr16"])
def test_link_points_lie_on_pybullets_collision_shapes(robot):
    """The points the spheres are fitted to are where PyBullet's shapes are: a tiny probe on
    one measures about -1 mm (the pad), or under +1 mm on a box's rounded corner."""
    spec = get_robot(robot)
    scene = Scene(spec)
    try:
        cid = scene.client
        probe = p.createCollisionShape(p.GEOM_SPHERE, radius=1e-4, physicsClientId=cid)
        scene.set_joints(np.asarray(spec.home) + 0.3)
        links = _collision_links(scene)
        for link, pose in zip(links, _link_poses(scene, links)):
            points = link_points(scene, link) @ pose[:3, :3].T + pose[:3, 3]
            for point in points[:: max(1, len(points) // 10)]:
                close = p.getClosestPoints(scene.robot, -1, 0.01, linkIndexA=link, collisionShapeB=probe,
                                           collisionShapePositionB=point.tolist(), physicsClientId=cid)
                assert close and -0.0012 < min(c[8] for c in close) < 0.001
    finally:
        scene.close()


def test_a_chain_holds_its_cylinder_and_is_no_fatter_than_it_must_be():
    a, b, r = np.zeros(3), np.array([0.0, 0.0, 0.35]), 0.05
    centres, radius = _chain(a, b, r, 1.0)
    assert len(centres) == 7 and radius == pytest.approx(math.hypot(r, 0.025))
    rng = np.random.default_rng(0)
    angle, height = rng.uniform(0, 2 * math.pi, 20000), rng.uniform(0, 0.35, 20000)
    height[:7] = np.arange(7) * 0.05  # rims where two spheres meet: the tightest places
    rim = np.stack([r * np.cos(angle), r * np.sin(angle), height], axis=1)
    reach = np.linalg.norm(rim[:, None] - centres[None], axis=2).min(axis=1)
    assert reach.max() <= radius + 1e-12
    assert reach.max() == pytest.approx(radius, abs=1e-9)


def test_candidates_read_only_a_worlds_own_obstacles():
    spec = get_robot("ur5")
    kin, scene = Kinematics(spec), Scene(spec)
    try:
        spheres = ArmSpheres.of(scene, kin)
    finally:
        scene.close()
    q = np.asarray(spec.home)
    frames = kin.frames(q)
    tip, down = kin.fk(q)[:3, 3], kin.fk(q)[:3, 2]  # the tool points along its z axis
    near = ObstacleSpec("sphere", tuple(tip + (0.04 + 0.001) * down), radius=0.04)
    far = ObstacleSpec("box", tuple(tip + [0.0, 0.0, -0.4]), half_extents=(0.05, 0.05, 0.05))
    centres = spheres.world(frames)
    assert (np.abs(centres - far.position).max(axis=1) - 0.05 - spheres.radius).min() > 0.1  # far from all
    batch = ObstacleBatch(3)
    batch.set_world(0, [near])
    batch.set_world(1, [far, near])
    batch.set_world(2, [])
    out = np.zeros(3, dtype=bool)
    assert candidates(np.repeat(frames[None], 3, axis=0), spheres, batch, out=out) is out
    assert out.tolist() == [True, True, False]
    batch.set_world(1, [far])
    assert candidates(np.repeat(frames[None], 3, axis=0), spheres, batch).tolist() == [True, False, False]
