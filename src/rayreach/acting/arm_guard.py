"""Keeping the arm off what the rays have seen.

The paper's rays watch the tool and the wrist's two cones; the arm's wrist and forearm
themselves are blind, and a KR16 wrist sweeping past a sphere the tool saw a moment earlier
is most of what that robot still strikes (docs/acting.md). The acting layers' ray memory
remembers where the rays hit over the last steps; ``ArmCapsules`` wraps the robot's
``blind_links`` in capsules fitted to their collision meshes and measures the seen points
near them against the meshes; ``ArmGuard`` refuses a step that brings a link nearer than
``clearance`` to a point that was seen. The tool carries rays but is blind between them: a
plate seen edge-on slips between the wraparound's rings and columns, and a tool that saw it
a few steps earlier swept its side into it; the rule can watch the tool as well. Only ray
data enters the rule, as for the rest of the safety layer.
"""

from __future__ import annotations

import numpy as np
import pybullet as p

from rayreach.sim.geometry import capsule_around, distances_to_segment
from rayreach.robots.urdf import TOOL_LINK
from rayreach.sim.scene import Scene
from rayreach.sim.voxels import cell_keys

VOXEL = 0.005
"""Seen points closer than this, m, are measured once (a static surface is hit again every step)."""

PROBE = 1e-4
"""Radius, m, of the sphere PyBullet measures a seen point as."""

PAD = 0.002
"""How much nearer than a capsule says, m, PyBullet may measure a point: it pads its meshes
by about a millimetre (``tests/test_arm_guard.py``)."""


class ArmCapsules:
    """The arm ``links`` (names), each with a capsule fitted once around its collision mesh
    in the link's frame: the capsules tell cheaply which seen points are near enough for
    PyBullet to measure against the mesh itself."""

    def __init__(self, scene: Scene, links: tuple[str, ...]) -> None:
        self.scene = scene
        unknown = [name for name in links if name not in scene.link_indices]
        if unknown:
            raise ValueError(f"robot '{scene.spec.name}' has no links {unknown}; it has {sorted(scene.link_indices)}")
        self.names = tuple(links)
        self.links: list[int] = []
        ends, radii = [], []
        for name in links:
            index = scene.link_indices[name]
            count, vertices = p.getMeshData(scene.robot, index, physicsClientId=scene.client)
            if count < 4:
                raise ValueError(f"link '{name}' of '{scene.spec.name}' has no collision mesh to wrap")
            a, b, r = capsule_around(np.asarray(vertices, dtype=float))
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

    def mask(self, leave_out: tuple[str, ...] = ()) -> np.ndarray:
        """Which links ``clearance`` measures (its ``use``): all but those named."""
        return np.array([name not in leave_out for name in self.names], dtype=bool)

    def clearance(self, points: np.ndarray, within: float,
                  ends: tuple[np.ndarray, np.ndarray] | None = None, use: np.ndarray | None = None) -> float:
        """Least distance, m, from ``points`` (n, 3) to the collision meshes of the links
        (those ``use`` marks, ``mask()``; None: all) in the scene's current joint state, as
        PyBullet measures it, or ``within`` if none is nearer. The capsules (``ends``:
        ``world()``'s, if already known) bound each point's distance from below, so points
        are measured nearest first, one per ``VOXEL``-sized cell, until the bound passes the
        nearest measured."""
        use = np.ones(len(self.links), dtype=bool) if use is None else use
        if not len(points) or not use.any():
            return within
        a, b = self.world() if ends is None else ends
        a, b, links, radii = a[use], b[use], np.asarray(self.links)[use], self.radii[use]
        # a sphere around each capsule first: a cheap product, where most points drop out
        middle, half = (a + b) / 2, np.linalg.norm(b - a, axis=1) / 2
        square = (points * points).sum(axis=1)[:, None] - 2 * points @ middle.T + (middle * middle).sum(axis=1)[None]
        points = points[(square < (half + radii + within)[None] ** 2).any(axis=1)]
        bound = np.stack([distances_to_segment(points, a[k], b[k] - a[k]) for k in range(len(a))], axis=1) - radii[None]
        best = within
        for k in np.flatnonzero((bound < within).any(axis=0)):
            order = np.argsort(bound[:, k])
            order = order[bound[order, k] < within]
            for i in order[_first_per_cell(points[order])]:
                if bound[i, k] - PAD >= best:
                    break
                close = p.getClosestPoints(self.scene.robot, -1, best, linkIndexA=int(links[k]),
                                           collisionShapeB=self._probe, collisionShapePositionB=points[i].tolist(),
                                           physicsClientId=self.scene.client)
                best = min([best, *(c[8] for c in close)])
        return float(best)


def _first_per_cell(points: np.ndarray) -> np.ndarray:
    """Indices, in order, of the first of ``points`` in each ``VOXEL``-sized cell (a static
    surface is hit again every step)."""
    _, first = np.unique(cell_keys(points, VOXEL), return_index=True)
    return np.sort(first)


class ArmGuard:
    """The arm's rule for one episode (``SafetyLayer.arm_clearance``): whether a joint step
    keeps the blind links clear of the points the rays have seen (``RayMemory.seen_points``),
    and the tool too where ``links`` holds it (``TOOL_LINK``) and ``tool`` is set
    (``SafetyLayer.guard_tool``), at ``tool_clearance`` (None: ``clearance``). Made where the
    scene's joints are at the start."""

    def __init__(self, links: ArmCapsules, clearance: float, tool: bool = False,
                 tool_clearance: float | None = None) -> None:
        self.scene = links.scene
        self.links = links
        arm = links.mask((TOOL_LINK,))
        only_tool = ~arm
        self._arm = [(arm, clearance)]
        self._with_tool = self._arm + ([(only_tool, clearance if tool_clearance is None else tool_clearance)]
                                       if tool and only_tool.any() else [])
        self._ends = self.links.world()  # where the last allowed step left the capsules

    def allows(self, q_now: np.ndarray, q: np.ndarray, points: np.ndarray, tool: bool = True) -> bool:
        """Whether moving the joints from ``q_now`` (where the last allowed step left them)
        to ``q`` keeps the arm links and the tool each their clearance from ``points`` (world,
        m, (n, 3)), or brings them no nearer than they are now; ``tool=False`` leaves the
        tool out this step. Leaves the scene's joints at ``q`` or ``q_now``."""
        self.scene.set_joints(q)
        ends = self.links.world()
        for use, clearance in self._with_tool if tool else self._arm:
            after = self.links.clearance(points, clearance, ends, use)
            if after < clearance:
                self.scene.set_joints(q_now)
                if after < self.links.clearance(points, clearance, self._ends, use):
                    return False
                self.scene.set_joints(q)
        self._ends = ends
        return True
