"""Keeping the arm off what the rays have seen.

The paper's rays watch the tool and the wrist's two cones; the arm's wrist and forearm
themselves are blind, and a KR16 wrist sweeping past a sphere the tool saw a moment earlier
is most of what that robot still strikes (docs/acting.md). The acting layers' ray memory
remembers where the rays hit over the last steps; ``ArmGuard`` refuses a step that brings a
link nearer than ``clearance`` to a point that was seen. The tool carries rays but is blind
between them: a plate seen edge-on slips between the wraparound's rings and columns, and a
tool that saw it a few steps earlier swept its side into it; the rule can watch the tool as
well. Only ray data enters the rule, as for the rest of the safety layer.

The links are capsules fitted to their collision meshes. In simulation PyBullet measures
the seen points near a capsule against the mesh itself (``rayreach.acting.mesh_capsules``);
on a real arm, without PyBullet, ``ChainCapsules`` holds the same capsules in the joint
chain's frames and measures against them, which never reads a point farther than the mesh
is (the capsule holds the mesh).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from importlib import resources
from typing import Protocol

import numpy as np

from rayreach.robots.spec import RobotSpec
from rayreach.robots.urdf import TOOL_LINK
from rayreach.sim.geometry import distances_to_segment
from rayreach.sim.kinematics import Kinematics
from rayreach.sim.sensors import ARM_MOUNTS


def guarded_links(spec: RobotSpec, arm_rays: bool) -> tuple[str, ...]:
    """The links the arm's rule keeps clear: the robot's blind links, with ``arm_rays``
    (``SafetyLayer.arm_rays``) the links its rays round the arm are mounted on too, then the tool."""
    links = list(spec.blind_links)
    if arm_rays:
        links += [link for link in dict.fromkeys(spec.mounts[m].link for m in ARM_MOUNTS) if link not in links]
    return (*links, TOOL_LINK)


CAPSULE_FILE = "arm_capsules.json"
"""Package data of ``rayreach.models``: each robot's capsules in its chain frames, fitted with
PyBullet (``python -m rayreach.acting.mesh_capsules`` writes it; a test holds it to a fresh fit)."""


class LinkCapsules(Protocol):
    """The arm's links as ``ArmGuard`` measures them."""

    names: tuple[str, ...]

    def pose(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Put the links at ``q``; their capsules' segment ends (k, 3) and (k, 3) in the world."""

    def mask(self, leave_out: tuple[str, ...] = ()) -> np.ndarray:
        """Which links ``clearance`` measures (its ``use``): all but those named."""

    def clearance(self, points: np.ndarray, within: float, ends: tuple[np.ndarray, np.ndarray],
                  use: np.ndarray | None = None) -> float:
        """Least distance, m, from ``points`` (n, 3) to the links ``use`` marks, posed where
        ``ends`` were taken, or ``within`` if none is nearer."""


def near_capsules(points: np.ndarray, a: np.ndarray, b: np.ndarray, radii: np.ndarray, within: float) -> tuple:
    """The points (n, 3) that may lie within ``within`` of a capsule (a sphere round each
    first: a cheap product, where most points drop out), and each one's distance to each
    capsule's surface (m, (n', k)), a lower bound of its distance to what the capsule holds."""
    middle, half = (a + b) / 2, np.linalg.norm(b - a, axis=1) / 2
    square = (points * points).sum(axis=1)[:, None] - 2 * points @ middle.T + (middle * middle).sum(axis=1)[None]
    points = points[(square < (half + radii + within)[None] ** 2).any(axis=1)]
    bound = np.stack([distances_to_segment(points, a[k], b[k] - a[k]) for k in range(len(a))], axis=1) - radii[None]
    return points, bound


@dataclass(frozen=True, eq=False)
class ChainCapsules:
    """The links' capsules fixed in the kinematic chain's frames: numpy only, for a controller
    of a real arm. ``frame[k]`` is the chain frame link k moves with; ``ends[k]`` its segment's
    two ends there (m); ``radii[k]`` its radius (m)."""

    kin: Kinematics
    names: tuple[str, ...]
    frame: np.ndarray
    ends: np.ndarray
    radii: np.ndarray

    @classmethod
    def shipped(cls, kin: Kinematics, links: tuple[str, ...] | None = None) -> ChainCapsules:
        """The robot's capsules from the package's ``CAPSULE_FILE``: its blind links and the tool
        (``links``: those named only)."""
        table = json.loads(resources.files("rayreach.models").joinpath(CAPSULE_FILE).read_text())
        name = kin.spec.name
        if name not in table:
            raise ValueError(f"no capsules shipped for robot '{name}' (shipped: {', '.join(sorted(table))}); "
                             "run python -m rayreach.acting.mesh_capsules with PyBullet installed")
        rows = {row["link"]: row for row in table[name]}
        links = tuple(rows) if links is None else links
        unknown = [link for link in links if link not in rows]
        if unknown:
            raise ValueError(f"robot '{name}' has no shipped capsule for {unknown}; it has {sorted(rows)}")
        return cls(kin, links, np.array([rows[k]["frame"] for k in links], dtype=int),
                   np.array([rows[k]["ends"] for k in links], dtype=float),
                   np.array([rows[k]["radius"] for k in links], dtype=float))

    def pose(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        frames = self.kin.frames(q)[self.frame]
        world = np.einsum("kij,kej->kei", frames[:, :3, :3], self.ends) + frames[:, None, :3, 3]
        return world[:, 0], world[:, 1]

    def mask(self, leave_out: tuple[str, ...] = ()) -> np.ndarray:
        return np.array([name not in leave_out for name in self.names], dtype=bool)

    def clearance(self, points: np.ndarray, within: float, ends: tuple[np.ndarray, np.ndarray],
                  use: np.ndarray | None = None) -> float:
        use = np.ones(len(self.names), dtype=bool) if use is None else use
        if not len(points) or not use.any():
            return within
        _, bound = near_capsules(points, ends[0][use], ends[1][use], self.radii[use], within)
        return float(min(within, bound.min())) if bound.size else within


class ArmGuard:
    """The arm's rule (``SafetyLayer.arm_clearance``): whether a joint step
    keeps the blind links clear of the points the rays have seen (``RayMemory.seen_points``),
    and the tool too where ``links`` holds it (``TOOL_LINK``) and ``tool`` is set
    (``SafetyLayer.guard_tool``), at ``tool_clearance`` (None: ``clearance``). It keeps no
    state: every step is measured from where the arm is."""

    def __init__(self, links: LinkCapsules, clearance: float, tool: bool = False,
                 tool_clearance: float | None = None) -> None:
        self.links = links
        arm = links.mask((TOOL_LINK,))
        only_tool = ~arm
        self._arm = [(arm, clearance)]
        self._with_tool = self._arm + ([(only_tool, clearance if tool_clearance is None else tool_clearance)]
                                       if tool and only_tool.any() else [])

    def allows(self, q_now: np.ndarray, q: np.ndarray, points: np.ndarray, tool: bool = True) -> bool:
        """Whether moving the joints from ``q_now`` to ``q`` keeps the arm links and the tool
        each their clearance from ``points`` (world, m, (n, 3)), or brings them no nearer than
        they are now; ``tool=False`` leaves the tool out this step. Leaves the links posed at
        ``q`` or ``q_now``."""
        ends = self.links.pose(q)
        for use, clearance in self._with_tool if tool else self._arm:
            after = self.links.clearance(points, clearance, ends, use)
            if after < clearance:
                now = self.links.pose(q_now)
                if after < self.links.clearance(points, clearance, now, use):
                    return False
                self.links.pose(q)  # PyBullet measures the links where they are posed
        return True
