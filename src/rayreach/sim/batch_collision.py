"""Collision tests for N worlds per step: a compiled broad phase, then PyBullet's own query.

The batched environment needs ``Scene.in_collision``'s answer for every world each step.
Asking PyBullet N times is most of a step's cost, and most worlds are nowhere near touching,
so the answer comes in two stages:

1. ``candidates``, compiled: the robot's links wrapped in spheres (``ArmSpheres``; each
   link's collision mesh in a capsule, ``geometry.capsule_around``, the capsule's cylinder in a
   chain of spheres), each inflated by ``MARGIN``, against every box and sphere of every
   world, a sphere around each link's chain first (2 to 3 times faster). A world none of
   whose spheres comes within reach of an obstacle cannot be in contact: the spheres hold
   the meshes, and ``MARGIN`` exceeds what PyBullet adds to them.
2. ``CollisionWorlds.in_collision``, only for the worlds flagged: one PyBullet client holds
   the robot and every world's obstacles as bare collision shapes, and asks PyBullet about
   the robot and world ``i``'s shapes pair by pair (``getClosestPoints`` at distance 0), so
   the answer is PyBullet's and other worlds never enter it. Not a ``Scene`` per world, nor
   all worlds' obstacles as bodies in one: PyBullet's collision pass, and moving the robot,
   cost in proportion to the bodies there.

``tests/test_batch_collision.py`` holds both to ``Scene.in_collision`` on random worlds;
``measure_false_alarms`` gives the share of flagged worlds not in contact.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Sequence

import numba
import numpy as np
import pybullet as p

from rayreach.robots import get_robot
from rayreach.robots.spec import RobotSpec
from rayreach.sim.batch_obstacles import BATCH_SHAPES, ObstacleBatch
from rayreach.sim.geometry import capsule_around
from rayreach.sim.kinematics import IKParams, Kinematics
from rayreach.sim.scene import Scene
from rayreach.sim.transforms import rpy_to_matrix

if TYPE_CHECKING:
    from rayreach.scenarios.schema import ObstacleSpec

MARGIN = 0.003
"""How far, m, beyond the spheres the broad phase looks. PyBullet pads the robot's convex
collision meshes by 1 mm (a point on a vertex measures -1 mm) and calls any negative
distance a contact, so contacts lie up to 1 mm outside the meshes; with a margin of 0
``candidates`` misses a few in 10,000 (``measure_false_alarms(robot, margin=0.0)``), with
1 mm none (``tests/test_batch_collision.py``); 3 mm leaves 2 mm for rounding and the
solver's tolerances."""

SPACING = 1.0
"""Greatest distance between neighbouring sphere centres along a capsule's axis, in units of
the capsule's radius: a sphere has at most ``sqrt(1 + SPACING^2 / 4)`` times that radius.
Halving it or doubling it moves the false alarms by a point or two
(``measure_false_alarms``) at about twice or half the 32 spheres per robot."""

RIGID = 1e-6
"""A link moves rigidly with a DH frame when its pose in the frame changes by less than this
(in every entry of the 4 x 4 matrix) from one configuration to another; the UR5's DH table
and URDF agree to 2e-11 m."""


def _pose(position: Sequence[float], orientation: Sequence[float]) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = np.asarray(p.getMatrixFromQuaternion(orientation)).reshape(3, 3)
    out[:3, 3] = position
    return out


def _collision_links(scene: Scene) -> list[int]:
    """The robot's links (-1: the base) that have a collision shape."""
    cid = scene.client
    links = [-1, *range(p.getNumJoints(scene.robot, physicsClientId=cid))]
    return [link for link in links if p.getCollisionShapeData(scene.robot, link, physicsClientId=cid)]


def _link_name(scene: Scene, link: int) -> str:
    cid = scene.client
    if link < 0:
        return p.getBodyInfo(scene.robot, physicsClientId=cid)[0].decode()
    return p.getJointInfo(scene.robot, link, physicsClientId=cid)[12].decode()


def _link_poses(scene: Scene, links: Sequence[int]) -> list[np.ndarray]:
    """World poses of the links' inertial frames, where PyBullet puts their collision shapes."""
    cid = scene.client
    out = []
    for link in links:
        if link < 0:
            out.append(_pose(*p.getBasePositionAndOrientation(scene.robot, physicsClientId=cid)))
        else:
            state = p.getLinkState(scene.robot, link, computeForwardKinematics=True, physicsClientId=cid)
            out.append(_pose(state[0], state[1]))
    return out


def link_points(scene: Scene, link: int) -> np.ndarray:
    """Points (n, 3), in the link's inertial frame, whose convex hull is the link's
    collision shape: a convex mesh's vertices (PyBullet makes URDF meshes and cylinders
    convex meshes), a box's corners (the UR5's ``ee_link``)."""
    cid = scene.client
    shapes = p.getCollisionShapeData(scene.robot, link, physicsClientId=cid)
    name = _link_name(scene, link)
    if len(shapes) != 1:
        raise ValueError(f"link '{name}' of '{scene.spec.name}' has {len(shapes)} collision shapes; "
                         "one is handled")
    geometry, dims = shapes[0][2], np.asarray(shapes[0][3], dtype=float)
    if geometry == p.GEOM_MESH:
        count, vertices = p.getMeshData(scene.robot, link, physicsClientId=cid)
        if count < 4:
            raise ValueError(f"link '{name}' of '{scene.spec.name}' has a collision mesh without vertices")
        return np.asarray(vertices, dtype=float)  # already in the inertial frame
    if geometry != p.GEOM_BOX:
        raise ValueError(f"link '{name}' of '{scene.spec.name}': collision geometry type {geometry} is not "
                         "handled (meshes and boxes are)")
    signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)])
    corners = signs * dims / 2  # dims: the box's sizes
    local = _pose(shapes[0][5], shapes[0][6])  # the box's frame in the inertial frame
    return corners @ local[:3, :3].T + local[:3, 3]


def _chain(a: np.ndarray, b: np.ndarray, r: float, spacing: float) -> tuple[np.ndarray, float]:
    """Centres (n, 3) and the radius of spheres that hold the cylinder of radius ``r`` about
    the segment from ``a`` to ``b``, which holds every point ``capsule_around`` wrapped (they lie
    within ``r`` of the segment and project onto it). The segment is cut into n pieces of
    length s at most ``spacing * r``; a sphere of radius ``sqrt(r^2 + (s/2)^2)`` about a
    piece's middle holds the cylinder's slice over the piece."""
    length = float(np.linalg.norm(b - a))
    n = max(1, int(math.ceil(length / (spacing * r))))
    step = length / n
    return a + ((np.arange(n) + 0.5) / n)[:, None] * (b - a), math.sqrt(r * r + step * step / 4)


@dataclass(frozen=True)
class ArmSpheres:
    """Spheres holding every collision shape of a robot, each fixed in a DH frame, link by
    link, and a sphere around each link's spheres for a cheap first test."""

    frame: np.ndarray
    """(K,) int64: the index into ``Kinematics.frames`` each sphere moves with."""
    centre: np.ndarray
    """(K, 3) centres in their DH frames."""
    radius: np.ndarray
    """(K,) radii, m."""
    links: np.ndarray
    """(L,) int64: the PyBullet links (-1: the base) the spheres wrap."""
    start: np.ndarray
    """(L + 1,) int64: link ``links[l]``'s spheres are ``start[l]:start[l + 1]``."""
    bound_centre: np.ndarray
    """(L, 3) centre, in the link's DH frame, of a sphere holding the link's spheres."""
    bound_radius: np.ndarray
    """(L,) its radius, m."""

    @classmethod
    def of(cls, scene: Scene, kin: Kinematics, spacing: float = SPACING) -> "ArmSpheres":
        """Fitted to ``scene``'s robot, whose base must be where ``kin`` puts it. Each link
        is matched to the DH frame it moves rigidly with by comparing PyBullet's link poses
        with ``kin.frames`` at a few configurations; the scene's joints are restored."""
        cid = scene.client
        saved = [s[0] for s in p.getJointStates(scene.robot, scene.joint_indices, physicsClientId=cid)]
        links = _collision_links(scene)
        rng = np.random.default_rng(0)
        configs = [np.asarray(kin.spec.home), *rng.uniform(kin.lower, kin.upper, (2, len(kin.lower)))]
        relative = []  # per configuration: (links, frames, 4, 4) poses of each link in each DH frame
        for q in configs:
            scene.set_joints(q)
            inverse = np.linalg.inv(kin.frames(q))
            relative.append(np.array([inverse @ pose for pose in _link_poses(scene, links)]))
        scene.set_joints(saved)
        change = np.max([np.abs(r - relative[0]).max(axis=(2, 3)) for r in relative[1:]], axis=0)
        frames, centres, radii, start, bound_centre, bound_radius = [], [], [], [0], [], []
        for j, link in enumerate(links):
            k = int(np.argmin(change[j]))
            if change[j, k] > RIGID:
                raise ValueError(f"link '{_link_name(scene, link)}' of '{kin.spec.name}' moves with "
                                 f"no DH frame (least change {change[j, k]:.1e})")
            a, b, r = capsule_around(link_points(scene, link))
            to_frame = relative[0][j, k]
            a, b = to_frame[:3, :3] @ a + to_frame[:3, 3], to_frame[:3, :3] @ b + to_frame[:3, 3]
            chain, radius = _chain(a, b, r, spacing)
            centres += list(chain)
            radii += [radius] * len(chain)
            frames += [k] * len(chain)
            start.append(len(frames))
            bound_centre.append((a + b) / 2)
            bound_radius.append(float(np.linalg.norm(chain[0] - (a + b) / 2)) + radius)
        return cls(np.asarray(frames, dtype=np.int64), np.asarray(centres, dtype=float),
                   np.asarray(radii, dtype=float), np.asarray(links, dtype=np.int64),
                   np.asarray(start, dtype=np.int64), np.asarray(bound_centre, dtype=float),
                   np.asarray(bound_radius, dtype=float))

    @property
    def bound_frame(self) -> np.ndarray:
        """(L,) the DH frame each link moves with."""
        return self.frame[self.start[:-1]]

    def world(self, frames: np.ndarray) -> np.ndarray:
        """Centres (K, 3) in the world for one world's DH ``frames`` (7, 4, 4)."""
        f = frames[self.frame]
        return np.einsum("kij,kj->ki", f[:, :3, :3], self.centre) + f[:, :3, 3]


def candidates(frames: np.ndarray, spheres: ArmSpheres, obstacles: ObstacleBatch, margin: float = MARGIN,
               out: np.ndarray | None = None) -> np.ndarray:
    """(N,) bool: which worlds may be in contact, for the worlds' DH ``frames`` (N, 7, 4, 4)
    and their obstacles where they are now. False is certain; True needs PyBullet."""
    if out is None:
        out = np.empty(len(frames), dtype=bool)
    b, s, arm = obstacles.boxes, obstacles.spheres, spheres
    _candidates(frames, arm.frame, arm.centre, arm.radius, arm.start, arm.bound_frame, arm.bound_centre,
                arm.bound_radius, b.pos, b.rot, b.size, b.count, s.pos, s.size, s.count, float(margin), out)
    return out


SHAPES_PER_CLIENT = 100_000
"""PyBullet never frees a collision shape (``removeCollisionShape`` is a stub that warns),
about 2.5 kB each; ``CollisionWorlds`` starts a fresh client after making this many."""


def _shape(obstacle: ObstacleSpec, client: int) -> int:
    """The collision shape of a box or sphere, as ``Scene._create_obstacle`` makes it."""
    if obstacle.shape == "box":
        return p.createCollisionShape(p.GEOM_BOX, halfExtents=list(obstacle.half_extents),
                                      physicsClientId=client)
    return p.createCollisionShape(p.GEOM_SPHERE, radius=obstacle.radius, physicsClientId=client)


class _World:
    """One world's obstacles in ``CollisionWorlds``: PyBullet collision shapes (no bodies)
    and the arrays ``_near`` reads."""

    def __init__(self, obstacles: Sequence[ObstacleSpec], client: int, n_links: int,
                 made: dict[int, int] | None = None) -> None:
        """``made``: shapes already made in ``client``, by ``id`` of the obstacle they were
        made for (a random world's draw asks twice about the same obstacles)."""
        made = made or {}
        unknown = sorted({o.shape for o in obstacles} - set(BATCH_SHAPES))
        if unknown:
            raise ValueError(f"CollisionWorlds handles {' and '.join(BATCH_SHAPES)} obstacles, "
                             f"not {', '.join(unknown)}")
        self.obstacles = list(obstacles)
        self.shapes = [made[id(o)] if id(o) in made else _shape(o, client) for o in obstacles]
        self.new_shapes = sum(id(o) not in made for o in obstacles)
        self.orientation = [p.getQuaternionFromEuler(o.rpy) for o in obstacles]
        self.moving = [k for k, o in enumerate(obstacles) if o.moving]
        n = len(obstacles)
        self.sphere = np.array([o.shape == "sphere" for o in obstacles], dtype=bool)
        self.pos = np.array([o.position for o in obstacles], dtype=float).reshape(n, 3)
        self.rot = np.array([rpy_to_matrix(o.rpy) for o in obstacles], dtype=float).reshape(n, 3, 3)
        sizes = [(o.radius, 0.0, 0.0) if o.shape == "sphere" else o.half_extents for o in obstacles]
        self.size = np.array(sizes, dtype=float).reshape(n, 3)
        self.near = np.zeros((n, n_links), dtype=bool)


class CollisionWorlds:
    """PyBullet's contact test of the robot against any of ``n_worlds`` worlds, from one
    client: the robot is a body, as in a ``Scene``, and each world's obstacles are bare
    collision shapes that PyBullet measures the robot against where the world has them
    (``getClosestPoints`` with a shape at a pose, at distance 0; a penetration is a contact).

    Why not the worlds' obstacles as bodies: ``Scene.in_collision`` runs PyBullet's whole
    collision pass, which costs in proportion to the bodies in the client (256 worlds of 3
    obstacles side by side on a grid: 25 times one world's), and even pair by pair, moving
    the robot from world to world, or its links among other worlds' obstacles, costs up to
    5 times more with 256 worlds of bodies than with one. Shapes are in no pair search; a shape
    query runs the narrow phase on one pair, and its penetrations are ``Scene.in_collision``'s
    contacts (``tests/test_batch_collision.py``)."""

    def __init__(self, spec: RobotSpec, n_worlds: int, base_position: Sequence[float] | None = None,
                 base_rpy: Sequence[float] | None = None) -> None:
        self._scene_args = (spec, base_position, base_rpy)
        self._scene = Scene(spec, base_position, base_rpy)
        self.kin = kin = Kinematics(spec, *(None if v is None else tuple(v)
                                            for v in (base_position, base_rpy)))
        self.spheres = ArmSpheres.of(self._scene, kin)
        self._links = [int(link) for link in self.spheres.links]
        self._bound_frame = self.spheres.bound_frame
        self._worlds = [_World([], self._scene.client, len(self._links)) for _ in range(n_worlds)]
        self._made = 0  # shapes made in this client

    def close(self) -> None:
        self._scene.close()

    def set_world(self, world: int, obstacles: Sequence[ObstacleSpec]) -> None:
        """Replace world ``world``'s obstacles (boxes and spheres, as ``ObstacleBatch``)."""
        old = self._worlds[world]
        made = dict(zip(map(id, old.obstacles), old.shapes))
        if self._made + len(obstacles) > SHAPES_PER_CLIENT:
            self._restart()
            made = {}
        self._worlds[world] = new = _World(obstacles, self._scene.client, len(self._links), made)
        self._made += new.new_shapes

    def slot(self, world: int) -> "WorldSlot":
        """World ``world`` as a ``Scene`` that random worlds are drawn in (``RandomWorlds``)."""
        return WorldSlot(self, world)

    def clearance(self, world: int, q: Sequence[float], within: float) -> float:
        """``Scene.clearance`` of world ``world`` at time 0 with the robot at joints ``q``."""
        cid, robot = self._scene.client, self._scene.robot
        w = self._worlds[world]
        self._scene.set_joints(q)
        distances = [c[8] for k, o in enumerate(w.obstacles)
                     for c in p.getClosestPoints(robot, -1, within, collisionShapeB=w.shapes[k],
                                                 collisionShapePositionB=list(o.position),
                                                 collisionShapeOrientationB=w.orientation[k],
                                                 physicsClientId=cid)]
        return min(distances, default=within)

    def _restart(self) -> None:
        """A fresh client with every world's obstacles, to give back the memory of old shapes."""
        self._scene.close()
        self._scene = Scene(*self._scene_args)
        self._worlds = [_World(w.obstacles, self._scene.client, len(self._links)) for w in self._worlds]
        self._made = sum(len(w.shapes) for w in self._worlds)

    def in_collision(self, world: int, q: Sequence[float], time: float,
                     frames: np.ndarray | None = None, margin: float = 0.0) -> bool:
        """``Scene.in_collision(margin)`` of world ``world`` alone with the robot at joints ``q``
        and its moving obstacles where they are at ``time``, s. With ``frames``, the DH frames
        of ``q`` (7, 4, 4), a link is asked about an obstacle only if its spheres come within
        ``MARGIN + margin`` of it (else it cannot come within ``margin``, as for
        ``candidates``); without, every link is."""
        cid, robot = self._scene.client, self._scene.robot
        w = self._worlds[world]
        self._scene.set_joints(q)
        for k in w.moving:
            w.pos[k] = w.obstacles[k].position_at(time)
        if frames is None:
            pairs = [(k, -2) for k in range(len(w.shapes))]  # -2: every link
        else:
            a = self.spheres
            _near(frames, a.frame, a.centre, a.radius, a.start, self._bound_frame, a.bound_centre,
                  a.bound_radius, w.sphere, w.pos, w.rot, w.size, MARGIN + margin, w.near)
            pairs = [(k, self._links[j]) for k, j in zip(*np.nonzero(w.near))]
        for k, link in pairs:
            close = p.getClosestPoints(robot, -1, margin, linkIndexA=link, collisionShapeB=w.shapes[k],
                                       collisionShapePositionB=w.pos[k].tolist(),
                                       collisionShapeOrientationB=w.orientation[k], physicsClientId=cid)
            if any(c[8] < margin for c in close):
                return True
        return False


class WorldSlot:
    """One world of a ``CollisionWorlds`` with the four calls ``RandomWorlds`` makes of a
    ``Scene`` (``random_world.WorldChecker``): a world is drawn where the batched env will
    test it, without PyBullet bodies, whose making costs most of a ``Scene``'s draw."""

    def __init__(self, worlds: CollisionWorlds, index: int) -> None:
        self.worlds = worlds
        self.index = index
        self.q = np.zeros(6)

    def set_obstacles(self, obstacles: Sequence[ObstacleSpec]) -> None:
        self.worlds.set_world(self.index, obstacles)

    def set_joints(self, q: Sequence[float]) -> None:
        self.q = np.asarray(q, dtype=float)

    def in_collision(self) -> bool:
        return self.worlds.in_collision(self.index, self.q, 0.0, self.worlds.kin.frames(self.q))

    def clearance(self, within: float) -> float:
        return self.worlds.clearance(self.index, self.q, within)


# ---------------------------------------------------------------------- compiled parts
@numba.njit(cache=True)
def _place(f, frame, centre, out):  # pragma: no cover - compiled
    """World centres (K, 3) of the spheres for one world's DH frames ``f`` (7, 4, 4)."""
    for k in range(len(frame)):
        m = f[frame[k]]
        c0, c1, c2 = centre[k, 0], centre[k, 1], centre[k, 2]
        for r in range(3):
            out[k, r] = m[r, 0] * c0 + m[r, 1] * c1 + m[r, 2] * c2 + m[r, 3]


@numba.njit(cache=True)
def _box_gap2(c, pos, rot, half):  # pragma: no cover - compiled
    """Squared distance from point ``c`` to a box (centre, world-from-box rotation, half extents)."""
    d0, d1, d2 = c[0] - pos[0], c[1] - pos[1], c[2] - pos[2]
    # into the box frame (rot^T d); past the half extents is what counts
    e0 = max(abs(rot[0, 0] * d0 + rot[1, 0] * d1 + rot[2, 0] * d2) - half[0], 0.0)
    e1 = max(abs(rot[0, 1] * d0 + rot[1, 1] * d1 + rot[2, 1] * d2) - half[1], 0.0)
    e2 = max(abs(rot[0, 2] * d0 + rot[1, 2] * d1 + rot[2, 2] * d2) - half[2], 0.0)
    return e0 * e0 + e1 * e1 + e2 * e2


@numba.njit(cache=True)
def _sphere_gap2(c, pos):  # pragma: no cover - compiled
    d0, d1, d2 = c[0] - pos[0], c[1] - pos[1], c[2] - pos[2]
    return d0 * d0 + d1 * d1 + d2 * d2


@numba.njit(cache=True)
def _box_near(g, world, start, radius, margin, pos, rot, half):  # pragma: no cover - compiled
    """Whether a sphere of link ``g`` (world centres ``world``) comes within ``margin`` of a box."""
    for k in range(start[g], start[g + 1]):
        reach = radius[k] + margin
        if _box_gap2(world[k], pos, rot, half) < reach * reach:
            return True
    return False


@numba.njit(cache=True)
def _ball_near(g, world, start, radius, margin, pos, ball):  # pragma: no cover - compiled
    """Whether a sphere of link ``g`` comes within ``margin`` of a sphere of radius ``ball``."""
    for k in range(start[g], start[g + 1]):
        reach = radius[k] + margin + ball
        if _sphere_gap2(world[k], pos) < reach * reach:
            return True
    return False


@numba.njit(cache=True)
def _candidates(frames, frame, centre, radius, start, bound_frame, bound_centre, bound_radius,
                box_pos, box_rot, box_half, n_box, sphere_pos, sphere_radius, n_sphere, margin,
                out):  # pragma: no cover - compiled
    """Each link's bound first, and the spheres placed only once a bound comes near."""
    world = np.empty((len(frame), 3))
    bound = np.empty((len(bound_frame), 3))
    for i in range(frames.shape[0]):
        _place(frames[i], bound_frame, bound_centre, bound)
        placed = hit = False
        for j in range(n_box[i]):
            h = box_half[i, j]
            extent = math.sqrt(h[0] * h[0] + h[1] * h[1] + h[2] * h[2])
            for g in range(len(bound_frame)):
                reach = bound_radius[g] + margin + extent
                if _sphere_gap2(bound[g], box_pos[i, j]) >= reach * reach:
                    continue
                if not placed:
                    _place(frames[i], frame, centre, world)
                    placed = True
                if _box_near(g, world, start, radius, margin, box_pos[i, j], box_rot[i, j], h):
                    hit = True
                    break
            if hit:
                break
        for j in range(0 if hit else n_sphere[i]):
            ball = sphere_radius[i, j, 0]
            for g in range(len(bound_frame)):
                reach = bound_radius[g] + margin + ball
                if _sphere_gap2(bound[g], sphere_pos[i, j]) >= reach * reach:
                    continue
                if not placed:
                    _place(frames[i], frame, centre, world)
                    placed = True
                if _ball_near(g, world, start, radius, margin, sphere_pos[i, j], ball):
                    hit = True
                    break
            if hit:
                break
        out[i] = hit


@numba.njit(cache=True)
def _near(f, frame, centre, radius, start, bound_frame, bound_centre, bound_radius, sphere, pos, rot, size,
          margin, out):  # pragma: no cover - compiled
    """``out[b, g]``: whether a sphere of link ``g`` comes within ``margin`` of obstacle ``b``
    (a sphere of radius ``size[b, 0]`` where ``sphere[b]``, else a box of half extents ``size[b]``)."""
    world = np.empty((len(frame), 3))
    bound = np.empty((len(bound_frame), 3))
    _place(f, frame, centre, world)
    _place(f, bound_frame, bound_centre, bound)
    for b in range(len(sphere)):
        s = size[b]
        extent = s[0] if sphere[b] else math.sqrt(s[0] * s[0] + s[1] * s[1] + s[2] * s[2])
        for g in range(len(bound_frame)):
            reach = bound_radius[g] + margin + extent
            if _sphere_gap2(bound[g], pos[b]) >= reach * reach:
                out[b, g] = False
            elif sphere[b]:
                out[b, g] = _ball_near(g, world, start, radius, margin, pos[b], s[0])
            else:
                out[b, g] = _box_near(g, world, start, radius, margin, pos[b], rot[b], s)


# ---------------------------------------------------------------------- measuring
NEAR = 0.05
"""``near_sample`` keeps configurations nearer than this, m, to an obstacle, or in contact."""


@dataclass(frozen=True)
class NearSample:
    """Configurations of a robot near the obstacles of random worlds, with PyBullet's verdict."""

    robot: str
    worlds: list[tuple[ObstacleSpec, ...]]
    world: np.ndarray
    """(n,) the world each configuration is in."""
    q: np.ndarray
    """(n, 6) joint angles."""
    time: np.ndarray
    """(n,) s since the world's start (where its moving obstacles are)."""
    contact: np.ndarray
    """(n,) ``Scene.in_collision``."""


def near_sample(robot: str, n: int, seed: int, per_world: int = 100, noise: float = 0.2) -> NearSample:
    """``n`` configurations near obstacles: random worlds (``RandomWorlds``, 3 obstacles,
    seeds below 1,000,000 drawn from ``seed``), each with its start and a tool-tip IK
    solution onto each of up to 3 obstacles as anchors, joint noise of a random scale up to
    ``noise`` rad on the anchors, kept when ``Scene.in_collision`` or nearer than ``NEAR``."""
    from rayreach.scenarios.random_world import RandomWorldConfig, RandomWorlds  # sim sits below scenarios

    spec = get_robot(robot)
    kin = Kinematics(spec)
    scene = Scene(spec)
    try:
        draw = RandomWorlds(kin, scene, RandomWorldConfig(n_obstacles=3))
        rng = np.random.default_rng(seed)
        worlds, world, qs, times, contact = [], [], [], [], []
        while len(qs) < n:
            scenario, q_start = draw.sample(np.random.default_rng(int(rng.integers(1_000_000))))
            obstacles = scenario.obstacles  # the scene holds them, at time 0
            t = float(rng.uniform(0.0, 3.0))
            scene.set_time(t)
            targets = [np.asarray(obstacles[k].position_at(t)) + rng.normal(0.0, 0.03, 3)
                       for k in rng.permutation(len(obstacles))[:3]]
            anchors = [q_start] + [kin.ik(target, None, q_start, _ANCHOR_IK).q for target in targets]
            kept, wanted = 0, min(per_world, n - len(qs))
            for k in range(_TRIES * per_world):  # an anchor may lie out of reach of every obstacle
                if kept == wanted:
                    break
                q = anchors[k % len(anchors)] + rng.normal(0.0, 1.0, 6) * rng.uniform(0.0, noise)
                scene.set_joints(q)
                hit = scene.in_collision()
                if hit or scene.clearance(NEAR) < NEAR:
                    world.append(len(worlds))
                    qs.append(q)
                    times.append(t)
                    contact.append(hit)
                    kept += 1
            worlds.append(obstacles)
    finally:
        scene.close()
    return NearSample(robot, worlds, np.asarray(world), np.asarray(qs), np.asarray(times),
                      np.asarray(contact, dtype=bool))


_ANCHOR_IK = IKParams(max_iterations=60)
_TRIES = 10


@dataclass(frozen=True)
class FalseAlarms:
    """How ``candidates`` did on a ``NearSample``."""

    n: int
    contacts: int
    """Configurations ``Scene.in_collision`` calls a contact."""
    flagged: int
    misses: int
    """Contacts ``candidates`` did not flag: must be 0."""
    share_of_flagged: float
    """False alarms (flagged, no contact) over flagged configurations."""
    share_of_all: float
    """False alarms over all configurations."""


def flag_sample(sample: NearSample, margin: float = MARGIN, spacing: float = SPACING) -> np.ndarray:
    """``candidates`` of every configuration of ``sample``, each as one world of a batch."""
    spec = get_robot(sample.robot)
    kin = Kinematics(spec)
    scene = Scene(spec)
    try:
        spheres = ArmSpheres.of(scene, kin, spacing)
    finally:
        scene.close()
    batch = ObstacleBatch(len(sample.q))
    for row, w in enumerate(sample.world):
        batch.set_world(row, sample.worlds[w])
    batch.at_time(sample.time)
    frames = np.array([kin.frames(q) for q in sample.q])
    return candidates(frames, spheres, batch, margin)


def measure_false_alarms(robot: str, n: int = 10_000, seed: int = 0, margin: float = MARGIN,
                         spacing: float = SPACING) -> FalseAlarms:
    """``candidates`` against ``Scene.in_collision`` on ``near_sample(robot, n, seed)``."""
    sample = near_sample(robot, n, seed)
    flagged = flag_sample(sample, margin, spacing)
    false = flagged & ~sample.contact
    return FalseAlarms(n=len(flagged), contacts=int(sample.contact.sum()), flagged=int(flagged.sum()),
                       misses=int((sample.contact & ~flagged).sum()),
                       share_of_flagged=float(false.sum() / max(flagged.sum(), 1)),
                       share_of_all=float(false.mean()))
