"""Keeping the arm off what the rays have seen.

The paper's rays watch the tool and the wrist's two cones; the arm's wrist and forearm
themselves are blind, and a KR16 wrist sweeping past a sphere the tool saw a moment earlier
is most of what that robot still strikes (docs/training.md, "Acting"). ``SeenPoints``
remembers where the rays hit over the last steps; ``ArmCapsules`` wraps the robot's
``blind_links`` in capsules fitted to their collision meshes and measures the seen points
near them against the meshes, so a step can be refused when it brings a link nearer than
``clearance`` to a point that was seen. Only ray data enters the rule, as for the rest
of the safety layer.
"""

from __future__ import annotations

from collections import deque

import numpy as np
import pybullet as p

from rayreach.scene import Scene

VOXEL = 0.005
"""Seen points closer than this, m, are kept once (a static surface is hit again every step)."""


PROBE = 1e-4
"""Radius, m, of the sphere PyBullet measures a seen point as."""


def _capsule(vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """The capsule (segment ends a, b and radius) around ``vertices`` along their principal
    axis: it holds every vertex, hence the convex mesh they span."""
    centre = vertices.mean(axis=0)
    axis = np.linalg.svd(vertices - centre, full_matrices=False)[2][0]
    along = (vertices - centre) @ axis
    a, b = centre + along.min() * axis, centre + along.max() * axis
    return a, b, float(segment_distances(vertices, a[None], b[None]).max())


def segment_distances(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Distance of each point (n, 3) to each segment from ``a[k]`` to ``b[k]`` (k, 3): (n, k)."""
    d = b - a
    rel = points[:, None, :] - a[None]
    length2 = np.maximum((d * d).sum(axis=1), 1e-18)
    t = np.clip((rel * d[None]).sum(axis=2) / length2, 0.0, 1.0)
    return np.linalg.norm(rel - t[..., None] * d[None], axis=2)


class ArmCapsules:
    """The arm ``links`` (names), each with a capsule fitted once around its collision mesh
    in the link's frame: the capsules tell cheaply which seen points are near enough for
    PyBullet to measure against the mesh itself."""

    def __init__(self, scene: Scene, links: tuple[str, ...]) -> None:
        self.scene = scene
        unknown = [name for name in links if name not in scene.link_indices]
        if unknown:
            raise ValueError(f"robot '{scene.spec.name}' has no links {unknown}; it has {sorted(scene.link_indices)}")
        self.links: list[int] = []
        ends, radii = [], []
        for name in links:
            index = scene.link_indices[name]
            count, vertices = p.getMeshData(scene.robot, index, physicsClientId=scene.client)
            if count < 4:
                raise ValueError(f"link '{name}' of '{scene.spec.name}' has no collision mesh to wrap")
            a, b, r = _capsule(np.asarray(vertices, dtype=float))
            self.links.append(index)
            ends.append((a, b))
            radii.append(r)
        self._ends = np.asarray(ends, dtype=float).reshape(-1, 2, 3)
        self.radii = np.asarray(radii, dtype=float)
        self._probe = p.createCollisionShape(p.GEOM_SPHERE, radius=PROBE, physicsClientId=scene.client)

    def world(self) -> tuple[np.ndarray, np.ndarray]:
        """Segment ends (k, 3) and (k, 3) where the scene's joints put the links now."""
        states = p.getLinkStates(self.scene.robot, self.links, computeForwardKinematics=True,
                                 physicsClientId=self.scene.client)
        a, b = np.empty((len(self.links), 3)), np.empty((len(self.links), 3))
        for k, state in enumerate(states):  # the collision mesh sits in the link's inertial frame
            rot = np.asarray(p.getMatrixFromQuaternion(state[1])).reshape(3, 3)
            a[k], b[k] = self._ends[k] @ rot.T + np.asarray(state[0])
        return a, b

    def clearance(self, points: np.ndarray, within: float) -> float:
        """Least distance, m, from ``points`` (n, 3) to the links' collision meshes in the
        scene's current joint state, as PyBullet measures it, or ``within`` if none is
        nearer. The capsules pick the points worth measuring."""
        if not len(points) or not len(self.links):
            return within
        a, b = self.world()
        best = within
        for i, k in zip(*np.nonzero(segment_distances(points, a, b) - self.radii[None] < within)):
            close = p.getClosestPoints(self.scene.robot, -1, best, linkIndexA=self.links[k], collisionShapeB=self._probe,
                                       collisionShapePositionB=points[i].tolist(), physicsClientId=self.scene.client)
            best = min([best, *(c[8] for c in close)])
        return float(best)


class SeenPoints:
    """Where the rays hit, in the world, over the last ``steps`` steps. Static obstacles stay
    where they were seen; a moving one leaves a trail."""

    def __init__(self, steps: int) -> None:
        self._steps: deque[tuple[np.ndarray, np.ndarray]] = deque(maxlen=int(steps))

    def add(self, points: np.ndarray) -> None:
        points = np.asarray(points, dtype=float).reshape(-1, 3)
        cells = np.floor(points / VOXEL).astype(np.int64) + _CELL_OFFSET
        self._steps.append((points, (cells[:, 0] << 42) | (cells[:, 1] << 21) | cells[:, 2]))

    def points(self) -> np.ndarray:
        """The remembered points, one per ``VOXEL``-sized cell."""
        if not self._steps:
            return np.zeros((0, 3))
        _, first = np.unique(np.concatenate([key for _, key in self._steps]), return_index=True)
        return np.concatenate([points for points, _ in self._steps])[first]


_CELL_OFFSET = 1 << 20
"""Cells are numbered from here in each axis (about 5 km either side of the origin at
``VOXEL``), so the three fit in one 63-bit key."""
