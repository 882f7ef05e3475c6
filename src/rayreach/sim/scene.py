"""One PyBullet world: a robot, obstacles, goal markers, collision queries and ray casting.

Every call passes this scene's own ``physicsClientId``, so any number of scenes (different
robots included) live side by side in one process.

Collision groups: the robot's links are in group ``ROBOT_GROUP`` and see only obstacles;
obstacles are in ``OBSTACLE_GROUP``. Rays are cast with mask ``OBSTACLE_GROUP``, so they
pass through the robot, and obstacles are never tested against each other.
"""

from __future__ import annotations

from contextlib import contextmanager
from typing import TYPE_CHECKING, Iterator, Sequence

import numpy as np
import pybullet as p

from rayreach.sim.quiet import c_stdout_suppressed
from rayreach.robots.spec import RobotSpec
from rayreach.robots.urdf import TCP_LINK, resolved_urdf
from rayreach.sim.sensors import BulletCaster, NumpyCaster, PrimitiveSet, RayCaster
from rayreach.sim.transforms import rpy_to_matrix

if TYPE_CHECKING:  # the scene builds what a scenario describes; it reads the fields, imports no loader
    from rayreach.scenarios.schema import ObstacleSpec

ROBOT_GROUP = 2
OBSTACLE_GROUP = 1
RAY_BACKENDS = ("auto", "numpy", "bullet")
OBSTACLE_COLOR = (0.55, 0.6, 0.7, 1.0)
GOAL_COLOR = (0.9, 0.1, 0.1, 0.8)


class Scene:
    """Owns a PyBullet client (DIRECT, or GUI with ``gui=True``) holding one robot."""

    def __init__(
        self,
        spec: RobotSpec,
        base_position: Sequence[float] | None = None,
        base_rpy: Sequence[float] | None = None,
        gui: bool = False,
    ) -> None:
        self.spec = spec
        self.client = p.connect(p.GUI if gui else p.DIRECT)
        if self.client < 0:
            raise RuntimeError("could not connect to PyBullet" + (" GUI (is there a display?)" if gui else ""))
        cid = self.client
        position = tuple(spec.base_position if base_position is None else base_position)
        rpy = tuple(spec.base_rpy if base_rpy is None else base_rpy)
        with self.no_rendering(), c_stdout_suppressed():
            self.robot = p.loadURDF(
                str(resolved_urdf(spec)),
                position,
                p.getQuaternionFromEuler(rpy),
                useFixedBase=True,
                flags=p.URDF_USE_MATERIAL_COLORS_FROM_MTL,
                physicsClientId=cid,
            )
        joints = {}
        links = {}
        for i in range(p.getNumJoints(self.robot, physicsClientId=cid)):
            info = p.getJointInfo(self.robot, i, physicsClientId=cid)
            joints[info[1].decode()] = i
            links[info[12].decode()] = i
        missing = [j for j in spec.joint_names if j not in joints]
        if missing:
            raise ValueError(f"robot '{spec.name}': URDF lacks joints {missing}; it has {sorted(joints)}")
        self.joint_indices = [joints[j] for j in spec.joint_names]
        self.link_indices = links
        self.tcp_link = links[TCP_LINK]
        for link in [-1, *links.values()]:
            p.setCollisionFilterGroupMask(self.robot, link, ROBOT_GROUP, OBSTACLE_GROUP, physicsClientId=cid)
        self.obstacles: list[ObstacleSpec] = []
        self._obstacle_ids: list[int] = []
        self._goal_ids: list[int] = []
        self._moving: list[int] = []
        self._primitives = PrimitiveSet.empty()
        self._prim_slot: list[tuple[str, int]] = []
        self.time = 0.0

    # ------------------------------------------------------------------ life cycle
    def close(self) -> None:
        if self.client >= 0:
            try:
                p.disconnect(physicsClientId=self.client)
            except p.error:
                pass
            self.client = -1

    def __del__(self) -> None:  # a forgotten scene must not leak its server
        self.close()

    @contextmanager
    def no_rendering(self) -> Iterator[None]:
        """Pause GUI rendering while many bodies are created (no effect in DIRECT mode)."""
        p.configureDebugVisualizer(p.COV_ENABLE_RENDERING, 0, physicsClientId=self.client)
        try:
            yield
        finally:
            p.configureDebugVisualizer(p.COV_ENABLE_RENDERING, 1, physicsClientId=self.client)

    # ------------------------------------------------------------------ robot
    def set_joints(self, q: Sequence[float]) -> None:
        p.resetJointStatesMultiDof(
            self.robot, self.joint_indices, [[float(v)] for v in q], physicsClientId=self.client
        )

    def tcp_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """PyBullet's own pose of the tool tip: position and (x, y, z, w) quaternion."""
        state = p.getLinkState(self.robot, self.tcp_link, computeForwardKinematics=True, physicsClientId=self.client)
        return np.array(state[4]), np.array(state[5])

    def link_pose(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        state = p.getLinkState(
            self.robot, self.link_indices[name], computeForwardKinematics=True, physicsClientId=self.client
        )
        return np.array(state[4]), np.array(state[5])

    # ------------------------------------------------------------------ obstacles
    def set_obstacles(self, obstacles: Sequence[ObstacleSpec]) -> None:
        """Replace all obstacles (time restarts at 0)."""
        cid = self.client
        with self.no_rendering():
            for body in self._obstacle_ids:
                p.removeBody(body, physicsClientId=cid)
            self.obstacles = list(obstacles)
            self._obstacle_ids = [self._create_obstacle(o) for o in self.obstacles]
        self._moving = [i for i, o in enumerate(self.obstacles) if o.moving]
        self._build_primitives()
        self.time = 0.0

    def _create_obstacle(self, obs: ObstacleSpec) -> int:
        cid = self.client
        if obs.shape == "box":
            kw = {"halfExtents": list(obs.half_extents)}  # type: ignore[arg-type]
            geom = p.GEOM_BOX
        elif obs.shape == "sphere":
            kw = {"radius": obs.radius}
            geom = p.GEOM_SPHERE
        elif obs.shape == "cylinder":
            kw = {"radius": obs.radius, "height": obs.height}
            geom = p.GEOM_CYLINDER
        else:
            kw = {"fileName": obs.file, "meshScale": list(obs.scale)}
            geom = p.GEOM_MESH
        collision = p.createCollisionShape(geom, physicsClientId=cid, **kw)
        visual_kw = dict(kw)
        if geom == p.GEOM_CYLINDER:
            visual_kw = {"radius": obs.radius, "length": obs.height}
        visual = p.createVisualShape(geom, rgbaColor=OBSTACLE_COLOR, physicsClientId=cid, **visual_kw)
        body = p.createMultiBody(
            baseMass=0.0,
            baseCollisionShapeIndex=collision,
            baseVisualShapeIndex=visual,
            basePosition=list(obs.position),
            baseOrientation=p.getQuaternionFromEuler(obs.rpy),
            physicsClientId=cid,
        )
        p.setCollisionFilterGroupMask(body, -1, OBSTACLE_GROUP, OBSTACLE_GROUP | ROBOT_GROUP, physicsClientId=cid)
        return body

    def _build_primitives(self) -> None:
        by_shape: dict[str, list[ObstacleSpec]] = {"box": [], "sphere": [], "cylinder": []}
        self._prim_slot = []
        for obs in self.obstacles:
            if obs.shape in by_shape:
                self._prim_slot.append((obs.shape, len(by_shape[obs.shape])))
                by_shape[obs.shape].append(obs)
            else:
                self._prim_slot.append(("mesh", -1))
        boxes, spheres, cyls = by_shape["box"], by_shape["sphere"], by_shape["cylinder"]

        def pos(items: list[ObstacleSpec]) -> np.ndarray:
            return np.array([o.position for o in items], dtype=float).reshape(-1, 3)

        def rot(items: list[ObstacleSpec]) -> np.ndarray:
            return np.array([rpy_to_matrix(o.rpy) for o in items], dtype=float).reshape(-1, 3, 3)

        self._primitives = PrimitiveSet(
            box_pos=pos(boxes),
            box_rot=rot(boxes),
            box_half=np.array([o.half_extents for o in boxes], dtype=float).reshape(-1, 3),
            sphere_pos=pos(spheres),
            sphere_radius=np.array([o.radius for o in spheres], dtype=float),
            cyl_pos=pos(cyls),
            cyl_rot=rot(cyls),
            cyl_radius=np.array([o.radius for o in cyls], dtype=float),
            cyl_half_height=np.array([(o.height or 0.0) / 2 for o in cyls], dtype=float),
        )

    @property
    def has_moving_obstacles(self) -> bool:
        return bool(self._moving)

    @property
    def all_primitive(self) -> bool:
        return all(o.shape != "mesh" for o in self.obstacles)

    def set_time(self, t: float) -> None:
        """Move every moving obstacle to where it is ``t`` seconds after the start."""
        self.time = t
        for i in self._moving:
            obs = self.obstacles[i]
            position = obs.position_at(t)
            p.resetBasePositionAndOrientation(
                self._obstacle_ids[i], position, p.getQuaternionFromEuler(obs.rpy), physicsClientId=self.client
            )
            shape, slot = self._prim_slot[i]
            if shape == "box":
                self._primitives.box_pos[slot] = position
            elif shape == "sphere":
                self._primitives.sphere_pos[slot] = position
            elif shape == "cylinder":
                self._primitives.cyl_pos[slot] = position

    def obstacle_positions(self) -> np.ndarray:
        return np.array([o.position_at(self.time) for o in self.obstacles]).reshape(-1, 3)

    # ------------------------------------------------------------------ goals
    def set_goal_markers(self, goals: Sequence[Sequence[float]], radius: float = 0.015) -> None:
        """Visual-only spheres (no collision shape: rays and contacts ignore them)."""
        cid = self.client
        for body in self._goal_ids:
            p.removeBody(body, physicsClientId=cid)
        visual = p.createVisualShape(p.GEOM_SPHERE, radius=radius, rgbaColor=GOAL_COLOR, physicsClientId=cid)
        self._goal_ids = [
            p.createMultiBody(baseMass=0.0, baseVisualShapeIndex=visual, basePosition=list(g), physicsClientId=cid)
            for g in goals
        ]

    # ------------------------------------------------------------------ queries
    def _penetrating_bodies(self) -> list[int]:
        cid = self.client
        p.performCollisionDetection(physicsClientId=cid)
        return [c[2] for c in p.getContactPoints(bodyA=self.robot, physicsClientId=cid) if c[8] < 0.0]

    def in_collision(self, margin: float = 0.0) -> bool:
        """Whether the robot (arm or tool) penetrates any obstacle in its current state; with
        ``margin``, m, whether it comes nearer than that to one."""
        if margin > 0.0:
            return self.clearance(margin) < margin
        return bool(self._penetrating_bodies())

    def clearance(self, within: float) -> float:
        """Least distance, m, between the robot (arm or tool) and any obstacle in its current
        state, or ``within`` when none is nearer than that."""
        cid = self.client
        distances = [c[8] for body in self._obstacle_ids
                     for c in p.getClosestPoints(self.robot, body, within, physicsClientId=cid)]
        return min(distances, default=within)

    def colliding_links(self) -> list[str]:
        """Names of the robot's links (its URDF's, "base" for the base) that penetrate an
        obstacle now: what a collision was made by, the arm or the tool."""
        cid = self.client
        p.performCollisionDetection(physicsClientId=cid)
        links = {c[3] for c in p.getContactPoints(bodyA=self.robot, physicsClientId=cid) if c[8] < 0.0}
        return sorted("base" if link < 0 else p.getJointInfo(self.robot, link, physicsClientId=cid)[12].decode()
                      for link in links)

    def colliding_obstacles(self) -> list[int]:
        """Indices (into ``self.obstacles``) of the obstacles the robot penetrates now."""
        index = {body: i for i, body in enumerate(self._obstacle_ids)}
        return sorted({index[b] for b in self._penetrating_bodies() if b in index})

    def caster(self, backend: str = "auto") -> RayCaster:
        """The ray casting backend: ``numpy`` (primitives only), ``bullet``, or ``auto``."""
        if backend not in RAY_BACKENDS:
            raise ValueError(f"unknown ray backend '{backend}'; known: {', '.join(RAY_BACKENDS)}")
        if backend == "auto":
            backend = "numpy" if self.all_primitive else "bullet"
        if backend == "numpy":
            if not self.all_primitive:
                raise ValueError("the numpy ray backend handles boxes, spheres and cylinders only; this scene has meshes")
            return NumpyCaster(self._primitives)
        return BulletCaster(self.client, OBSTACLE_GROUP)

    # ------------------------------------------------------------------ camera
    def camera_image(
        self,
        width: int = 640,
        height: int = 480,
        target: Sequence[float] = (0.0, 0.3, 0.4),
        distance: float = 1.6,
        yaw: float = 210.0,
        pitch: float = -25.0,
        fov: float = 50.0,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """RGB image (h, w, 3 uint8) from PyBullet's headless renderer, with its view and
        projection matrices (column-major 4x4, as PyBullet returns them) for overlays."""
        cid = self.client
        view = p.computeViewMatrixFromYawPitchRoll(list(target), distance, yaw, pitch, 0.0, 2, physicsClientId=cid)
        proj = p.computeProjectionMatrixFOV(fov, width / height, 0.02, 20.0, physicsClientId=cid)
        _, _, rgba, _, _ = p.getCameraImage(
            width, height, view, proj, renderer=p.ER_TINY_RENDERER, physicsClientId=cid
        )
        image = np.reshape(np.asarray(rgba, dtype=np.uint8), (height, width, 4))[:, :, :3]
        return image, np.array(view).reshape(4, 4).T, np.array(proj).reshape(4, 4).T


def project_points(points: np.ndarray, view: np.ndarray, proj: np.ndarray, width: int, height: int) -> np.ndarray:
    """Pixel coordinates (n, 2) of world points for a camera from :meth:`Scene.camera_image`."""
    homog = np.concatenate((points, np.ones((len(points), 1))), axis=1)
    clip = (proj @ view @ homog.T).T
    ndc = clip[:, :3] / clip[:, 3:4]
    return np.stack(((ndc[:, 0] + 1) * 0.5 * width, (1 - ndc[:, 1]) * 0.5 * height), axis=1)

