"""The arm's links as PyBullet holds them: capsules fitted to the collision meshes, and the
seen points near a capsule measured against the mesh itself (``ArmCapsules``).

The same capsules, expressed in the joint chain's frames, are package data
(``rayreach.acting.arm_guard.CAPSULE_FILE``) for the controller of a real arm, which runs
without PyBullet; ``python -m rayreach.acting.mesh_capsules`` writes them.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pybullet as p

from rayreach.acting.arm_guard import CAPSULE_FILE, guarded_links, near_capsules
from rayreach.sim.geometry import capsule_around
from rayreach.sim.kinematics import Kinematics
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
    PyBullet to measure against the mesh itself (``arm_guard.LinkCapsules``)."""

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

    def pose(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Set the scene's joints to ``q``; the segment ends there."""
        self.scene.set_joints(q)
        return self.world()

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
        points, bound = near_capsules(points, a, b, radii, within)
        best = within
        for k in np.flatnonzero((bound < within).any(axis=0)):
            order = np.argsort(bound[:, k])
            order = order[bound[order, k] < within]
            for i in order[first_per_cell(points[order])]:
                if bound[i, k] - PAD >= best:
                    break
                close = p.getClosestPoints(self.scene.robot, -1, best, linkIndexA=int(links[k]),
                                           collisionShapeB=self._probe, collisionShapePositionB=points[i].tolist(),
                                           physicsClientId=self.scene.client)
                best = min([best, *(c[8] for c in close)])
        return float(best)


def first_per_cell(points: np.ndarray) -> np.ndarray:
    """Indices, in order, of the first of ``points`` in each ``VOXEL``-sized cell (a static
    surface is hit again every step)."""
    _, first = np.unique(cell_keys(points, VOXEL), return_index=True)
    return np.sort(first)


def chain_capsule_rows(scene: Scene, kin: Kinematics, links: tuple[str, ...]) -> list[dict]:
    """Each link's capsule in the chain frame it moves with: the frame whose pose relative to
    the link stays the same between two configurations (``scene`` and ``kin`` at one base pose)."""
    capsules = ArmCapsules(scene, links)
    rng = np.random.default_rng(0)
    qs = [np.asarray(scene.spec.home) + rng.uniform(-0.6, 0.6, len(scene.spec.home)) for _ in range(2)]
    ends, frames = [], []
    for q in qs:
        ends.append(np.stack(capsules.pose(q), axis=1))  # (k, 2, 3)
        frames.append(kin.frames(q))
    rows = []
    for k, name in enumerate(links):
        # the ends in every chain frame, per configuration: R^T (end - origin), (n + 1, 2, 3)
        local = [np.einsum("nji,nej->nei", f[:, :3, :3], e[k][None] - f[:, None, :3, 3]) for f, e in zip(frames, ends)]
        spread = np.abs(local[0] - local[1]).max(axis=(1, 2))  # per frame: how far the ends move in it
        frame = int(np.argmin(spread))
        if spread[frame] > 1e-6:
            raise ValueError(f"link '{name}' of '{scene.spec.name}' moves in every chain frame (least: "
                             f"{spread[frame]:.2e} m)")
        rows.append({"link": name, "frame": frame, "ends": local[0][frame].round(9).tolist(),
                     "radius": round(float(capsules.radii[k]), 9)})
    return rows


def capsule_table(robots: tuple[str, ...] | None = None) -> dict[str, list[dict]]:
    """``CAPSULE_FILE``'s content, fitted now: each robot's links the arm's rule may keep clear
    (``guarded_links`` with ``arm_rays``: the blind links, the upper arm, the forearm) and its tool."""
    from rayreach.robots import ROBOTS, get_robot

    table = {}
    for name in robots or tuple(ROBOTS):
        spec = get_robot(name)
        scene = Scene(spec)
        try:
            table[name] = chain_capsule_rows(scene, Kinematics(spec), guarded_links(spec, arm_rays=True))
        finally:
            scene.close()
    return table


if __name__ == "__main__":  # writes the package data next to the shipped policies
    from rayreach.planners.drl import MODELS_DIR

    target = Path(MODELS_DIR) / CAPSULE_FILE
    target.write_text(json.dumps(capsule_table(), indent=1) + "\n")
    print(f"wrote {target}")
