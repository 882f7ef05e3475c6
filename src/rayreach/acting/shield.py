"""A safety layer between a policy's action and the arm: not in the paper, off in training
(unless ``rayreach train --acting-layers``).

A trained policy still drives into what its rays see and out of the workspace now and then
(docs/acting.md). A cell's controller would not let it: a safety zone holds the
tool inside the workspace, and speed and separation monitoring stops motion towards a
nearby obstacle. ``SafetyLayer`` does both with what the agent itself observes (its rays,
its end-effector position) plus the workspace bounds; it never looks at the obstacles.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar, Sequence

import numpy as np

from rayreach.env.perception import Perception

if TYPE_CHECKING:
    from rayreach.acting.memory import Scan


@dataclass(frozen=True)
class SafetyLayer:
    TOLERANCE: ClassVar[float] = 1e-9
    """Motion towards a near ray or a bound below this, m, counts as none."""

    workspace_guard: float = 0.0
    """Drop the translation towards a workspace bound once a step as long as the commanded
    one could bring the end effector within this distance of it, m, so the tool slides
    along the bound; 0: off (leaving the workspace ends the episode with the paper's
    penalty)."""
    ray_shield: float = 0.0
    """When a ray sees something nearer than this, m, drop the translation along that ray
    (towards what it sees) and the whole rotation; 0: off."""
    slide: float = 0.0
    """When the rules leave less than this share of the commanded translation (a policy
    pushing straight into what it sees holds still until its step budget runs out), take the
    step towards the goal instead, through the same rules and without rotation: the tool
    slides along what it sees towards the goal. When the rules hold that step too, take a
    step as long along the allowed direction nearest the goal's, sideways or back if need
    be, so the policy acts again from a new place; 0: off."""
    memory_steps: int = 0
    """The shield also holds off what the rays saw near in the last this many steps
    (``remembered_rays``): as the tool moves, an obstacle's edge passes between two rings of rays
    and no ray sees what the next step strikes; 0: off."""
    arm_clearance: float = 0.0
    """Refuse a step (the arm holds still) that brings an arm link nearer than this, m, to a
    point the rays hit in the last ``arm_memory_steps`` steps, and nearer than the link is
    now (``rayreach.acting.arm_guard``): the arm's wrist and forearm carry no rays, and sweep into
    what the tool saw moments before; 0: off."""
    arm_memory_steps: int = 100
    """How many steps of ray hits ``arm_clearance`` keeps; steps in which the arm held still
    do not count (it would forget what it is held off, and move into it)."""
    guard_tool: bool = False
    """The arm's rule watches the tool itself too, except on the final approach's steps
    (``rayreach.acting.final_approach.FinalApproach``), whose straight path is tested against every hit
    with the tool's shape already and may pass a wall nearer than ``arm_clearance``. A thin
    plate seen edge-on slips between the rays; a tool that saw it a few steps earlier swept
    its side into it (docs/acting.md)."""
    arm_rays: bool = False
    """The arm's rule also keeps the upper arm and the forearm clear, of what the tool's rays
    saw and of what the rays round those two links see (``rayreach.sim.sensors.arm_layout``,
    cast for the rule whether the policy reads them or not). In broad worlds those links
    touched something in about two of five collisions (docs/training.md, "What the arm
    hits"), often a shelf or wall the tool never came near."""
    tool_clearance: float | None = None
    """The clearance, m, the arm's rule keeps the tool at when ``guard_tool`` is set; None:
    ``arm_clearance``. The tool and the arm links are each held to their own: a plate's
    edge lies a centimetre or two beyond the last point the rays hit on its face."""

    @property
    def reads_arm_rays(self) -> bool:
        """Whether the arm's rule is on and reads the rays round the upper arm and the forearm."""
        return self.arm_rays and self.arm_clearance > 0

    def __post_init__(self) -> None:
        for name in ("workspace_guard", "ray_shield", "slide", "memory_steps", "arm_clearance", "arm_memory_steps"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name} must be >= 0 (0 = off), got {getattr(self, name)}")
        for name in ("memory_steps", "arm_memory_steps"):
            if getattr(self, name) != int(getattr(self, name)):
                raise ValueError(f"{name} counts steps, a whole number, got {getattr(self, name)}")
        if self.tool_clearance is not None and not self.tool_clearance > 0:
            raise ValueError(f"tool_clearance must be > 0 (None: arm_clearance), got {self.tool_clearance}")
        if not isinstance(self.guard_tool, (bool, np.bool_)):
            raise ValueError(f"guard_tool is True or False, got {self.guard_tool!r}")
        if self.slide > 1:
            raise ValueError(f"slide is a share of the commanded step, 0 to 1, got {self.slide}")

    @property
    def active(self) -> bool:
        """Whether ``filter`` changes anything (the arm's rule is a component of its own,
        ``rayreach.acting.layers.ArmRule``)."""
        return self.workspace_guard > 0 or self.ray_shield > 0

    def filter(self, delta: np.ndarray, ee_pos: np.ndarray, low: np.ndarray, high: np.ndarray,
               ray_distances: np.ndarray, ray_directions: np.ndarray, travel: float | None = None,
               towards_goal: np.ndarray | None = None, keep_rotation: bool = False) -> np.ndarray:
        """``shape``'s step alone."""
        return self.shape(delta, ee_pos, low, high, ray_distances, ray_directions, travel, towards_goal,
                          keep_rotation)[0]

    def shape(self, delta: np.ndarray, ee_pos: np.ndarray, low: np.ndarray, high: np.ndarray,
              ray_distances: np.ndarray, ray_directions: np.ndarray, travel: float | None = None,
              towards_goal: np.ndarray | None = None, keep_rotation: bool = False) -> tuple[np.ndarray, bool]:
        """(step, slid): ``delta`` (dx, dy, dz, rotation vector) as the arm may execute it.
        ``ray_distances`` (m) and unit ``ray_directions`` are those of the current observation. ``travel``: how
        far, m, the motion goes in all when that is known (a straight path to the goal); if
        every ray sees farther than that, nothing seen can be reached and the shield lets
        the motion through. Without it, a goal a few centimetres from a wall could not be
        reached: the wall stays within the shield all the way in. ``towards_goal``: the
        translation ``slide`` takes instead (None: no slide). ``keep_rotation``: the rotation
        was tested against what the rays see already (the final approach's turn), so a near
        ray does not drop it.

        Each rule is a half-space through the origin that the translation must lie in, so
        the translation kept is the nearest one to the commanded that lies in all of them
        (``nearest_in_cone``). ``slid``: the slide replaced the step by one towards the goal."""
        bounds = (ee_pos, low, high)
        near = ray_directions[self._near(ray_distances, travel)]
        out = np.array(delta, dtype=float)
        if len(near) and not keep_rotation:
            out[3:] = 0.0
        out[:3] = nearest_in_cone(out[:3], self._normals(float(np.linalg.norm(out[:3])), *bounds, near), self.TOLERANCE)
        least = self.slide * np.linalg.norm(delta[:3])
        slid = bool(self.slide > 0 and towards_goal is not None and np.linalg.norm(out[:3]) < least)
        if slid:
            size = float(np.linalg.norm(towards_goal))
            # the rules for the goal's step, once for both tries
            normals = self._normals(size, *bounds, ray_directions[self._near(ray_distances, None)])
            out = np.zeros(6)
            out[:3] = nearest_in_cone(np.asarray(towards_goal, dtype=float), normals, self.TOLERANCE)
            if np.linalg.norm(out[:3]) < least and size > 0:
                way = nearest_direction_in_cone(towards_goal, normals, self.TOLERANCE)
                if way is not None:
                    out[:3] = way * size
        return out, slid

    def allows(self, move: np.ndarray, ee_pos: np.ndarray, low: np.ndarray, high: np.ndarray,
               ray_distances: np.ndarray, ray_directions: np.ndarray, travel: float | None = None,
               tolerance: float = 1e-4) -> bool:
        """Whether the translation ``move`` goes at most ``tolerance`` (m) towards a near ray or
        a bound under the same rules as ``filter``: the check of where IK put the tool, which,
        when IK does not converge, is not the step the layer let through."""
        near = ray_directions[self._near(ray_distances, travel)]
        normals = self._normals(float(np.linalg.norm(move)), ee_pos, low, high, near)
        return bool(np.all(normals @ move <= tolerance))

    def _near(self, ray_distances: np.ndarray, travel: float | None) -> np.ndarray:
        """Indices of the rays the shield holds off: those nearer than ``ray_shield``, when the
        shield is on and the motion's ``travel`` (when known) reaches as far as the nearest
        thing a ray sees."""
        if self.ray_shield <= 0 or (travel is not None and travel < ray_distances.min(initial=np.inf)):
            return np.zeros(0, int)
        return np.flatnonzero(ray_distances < self.ray_shield)

    def _normals(self, reach: float, ee_pos: np.ndarray, low: np.ndarray, high: np.ndarray,
                 near_directions: np.ndarray) -> np.ndarray:
        """The rules for a step of length ``reach`` as unit normals of the half-spaces
        {m : normal @ m <= 0}: every near ray's direction, and every bound within the step
        of its band."""
        normals = [near_directions.reshape(-1, 3)]
        if self.workspace_guard > 0:
            axes = np.eye(3)
            normals += [axes[ee_pos + reach > high - self.workspace_guard],
                        -axes[ee_pos - reach < low + self.workspace_guard]]
        return np.concatenate(normals)


MARGIN = 0.01
"""Hits up to this much farther than the shield are remembered too, m: a step may bring
them within it (``remembered_rays``)."""

LOST = 0.01
"""A remembered point counts as out of sight when no ray hits within this of it now, m;
points still in sight are the current rays' to hold off."""


def near_hits(perception: Perception, reach: float) -> tuple[np.ndarray, np.ndarray]:
    """The points one scan's rays hit within ``reach`` plus ``MARGIN`` (world, m) and their
    rays' origins relative to the end effector then, (k, 3) each."""
    hit = perception.lengths < reach + MARGIN
    points = perception.origins[hit] + perception.directions[hit] * perception.lengths[hit, None]
    return points, perception.origins[hit] - perception.ee_position


def remembered_rays(now: Perception, before: Sequence[Scan], reach: float) -> tuple[np.ndarray, np.ndarray]:
    """(distances, unit directions) for the shield: the current rays, then one per point the
    rays hit in the scans ``before`` (``RayMemory.before``) that is within ``reach`` of its
    ray's origin where that origin is now (moved with the end effector) and out of sight
    (``LOST``). As the tool moves, an obstacle's edge passes between two rings of rays and no
    ray sees what the next step strikes; static obstacles stay where they were seen, and a
    moving one leaves a trail the shield keeps clear of."""
    if not before:
        return now.lengths, now.directions
    seen = [scan.view(("shield", reach), lambda p: near_hits(p, reach)) for scan in before]
    points = np.concatenate([p for p, _ in seen])
    towards = points - (now.ee_position + np.concatenate([o for _, o in seen]))
    size = np.linalg.norm(towards, axis=1)
    near = np.flatnonzero((size < reach) & (size > 0))
    in_sight = near_hits(now, reach)[0]
    if len(in_sight) and len(near):  # only what no ray sees any more
        gap = ((points[near, None] - in_sight[None]) ** 2).sum(axis=2).min(axis=1)
        near = near[gap > LOST ** 2]
    return (np.concatenate([now.lengths, size[near]]),
            np.concatenate([now.directions, towards[near] / size[near, None]]))


TIE = 1e-3
"""Cosine difference under which two allowed directions count as equally near the goal's
(``nearest_direction_in_cone``)."""


def _edge_lines(normals: np.ndarray) -> np.ndarray:
    """Unit directions of the lines that pairs of the planes share (parallel pairs skipped)."""
    i, j = np.triu_indices(len(normals), k=1)
    lines = np.cross(normals[i], normals[j])
    size = np.linalg.norm(lines, axis=1)
    return lines[size > 1e-9] / size[size > 1e-9, None]


def nearest_direction_in_cone(direction: np.ndarray, normals: np.ndarray, tolerance: float = 0.0) -> np.ndarray | None:
    """The unit vector at the smallest angle to ``direction`` that goes towards none of the
    unit ``normals``; None when the cone {m : normals @ m <= 0} is its apex alone.

    The angle is smallest at ``direction`` itself, on a face (``direction`` projected onto
    its plane) or on an edge (either way along it); the best of those inside the cone. Where
    ``direction`` is inside the cone's polar, every allowed direction leads away from it and
    this is the one that leads away least. Near ties (within ``TIE``; a goal straight behind
    a wall) go to the left of ``direction`` about the world's z axis, so that the choice does
    not hang on rounding."""
    g = direction / np.linalg.norm(direction)
    faces = g - (normals @ g)[:, None] * normals
    size = np.linalg.norm(faces, axis=1)
    faces = faces[size > 1e-9] / size[size > 1e-9, None]
    lines = _edge_lines(normals)
    candidates = np.concatenate([g[None], faces, lines, -lines])
    candidates = candidates[np.all(candidates @ normals.T <= tolerance + 1e-12, axis=1)]  # + rounding
    if not len(candidates):
        return None
    left = np.cross([0.0, 0.0, 1.0], g)
    left = left / np.linalg.norm(left) if np.linalg.norm(left) > 1e-9 else np.array([1.0, 0.0, 0.0])
    return candidates[np.argmax(candidates @ g + TIE * (candidates @ left))]


def nearest_in_cone(move: np.ndarray, normals: np.ndarray, tolerance: float = 0.0) -> np.ndarray:
    """The translation nearest ``move`` that goes towards none of the unit ``normals``: the
    projection onto the cone {m : normals @ m <= 0}.

    In three dimensions that point lies inside the cone (``move`` itself), on one of its
    faces (``move`` projected onto one plane), on one of its edges (projected onto the line
    two planes share) or at its apex, and it is the nearest of those candidates that lies in
    the cone. A face is tried first: the cone lies within each half-space, so a plane that
    ``move`` crosses, projected onto and found inside the cone, is the answer; the edges,
    pairwise and costlier, only when none is. Exact, where projecting onto one plane after
    another creeps towards the answer: a ray 40 degrees off a bound left 2e-8 m of motion
    towards it after 20 rounds (tests/test_safety.py)."""
    towards = normals @ move if len(normals) else np.zeros(0)
    if np.all(towards <= tolerance):
        return move
    tolerance += 1e-9 * float(np.linalg.norm(move))  # the candidates' rounding
    for i in np.flatnonzero(towards > tolerance)[np.argsort(towards[towards > tolerance])]:
        face = move - towards[i] * normals[i]
        if np.all(normals @ face <= tolerance):
            return face
    lines = _edge_lines(normals)
    candidates = np.concatenate([(lines @ move)[:, None] * lines, np.zeros((1, 3))])
    candidates = candidates[np.all(candidates @ normals.T <= tolerance, axis=1)]
    return candidates[np.argmin(np.linalg.norm(candidates - move, axis=1))]


ACTING_SAFETY = SafetyLayer(workspace_guard=0.01, ray_shield=0.05, memory_steps=10, arm_clearance=0.01,
                            guard_tool=True, tool_clearance=0.02)
"""The layer the executor and ``rollout`` act with: two 5 mm steps from a bound, a 5 cm
shield (chosen from 3, 5 and 8 cm on random worlds) that remembers the last 10 steps' near
hits (10, 20 and 40 measured alike), and the arm held 1 cm and the tool 2 cm off what the
rays saw in the last 100 moving steps (1 and 2 cm, 100 to 1024 steps measured for the arm;
1, 1.5 and 2 cm for the tool on its own). No slide: with neither shipped policy did it earn
its place on the validation split (``SLIDE`` turns it on; docs/acting.md)."""

SLIDE = 0.1
"""The slide's share (``SafetyLayer.slide``) where it is asked for: once less than a tenth
of the commanded step is left (``rollout --slide 0.1``)."""
