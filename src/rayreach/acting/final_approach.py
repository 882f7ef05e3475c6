"""The straight final step at a goal the policy has nearly reached. Not in the paper."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar, Sequence

import numpy as np

from rayreach.sim.geometry import distances_to_parallelogram, distances_to_segment
from rayreach.sim.transforms import rotvec_to_matrix


@dataclass(frozen=True)
class FinalApproach:
    """Step straight at the goal once the policy has brought the end effector within
    ``radius`` and everything the rays see lies at least ``margin`` from the tool on that
    straight path.

    Not in the paper. The mean action of a PPO policy trained with an enlarged goal tends to
    settle a few centimetres from the goal (the sampling noise did the last centimetres in
    training), so a deterministic rollout times out beside a goal it has reached in all but
    name (docs/acting.md). ``rayreach.acting.ActingEnv`` applies it,
    where the rays' hit points are known, and sets the robot's step and tool (and radii,
    unless given). The straight path is ``radius`` long at
    most (``axial_radius`` along the tool's axis). Where only the tool's back blocks it, the
    tool first turns about its tip towards the path (``turn``). From farther away it can
    nudge a policy that has stalled towards the goal (``stall_steps``, off by default)."""

    NEARER: ClassVar[float] = 0.001
    """How much nearer, m, the path may bring the tool to what it sees than the nearest hit
    is now, once that is within the margin (rounding, not a distance that matters)."""
    TURNED: ClassVar[float] = 1e-3
    """Angle, rad, between the tool and its path under which the tool counts as pointing
    along it (``turn``)."""

    radius: float | None = None
    """None: the robot's (``rayreach.acting.config.ROBOT_RADII``), which ``ActingEnv`` fills
    in. The UR5's is the enlarged goal the curriculum trains at (0.1 m), which the policy
    reliably comes this close to; from 0.13 m on, its straight paths ran under moving goal
    covers whose thin edges no ray saw, and the tool met them. The KR16's is 0.2 m, where it
    met nothing more."""
    axial_radius: float | None = None
    """None: the robot's (``rayreach.acting.config.ROBOT_RADII``). From within this
    distance too, m, but only where the path lies within ``axial_angle`` of the tool's axis:
    a tool moving along its own axis sweeps little more than the cone its tip rays look
    into. The UR5's policy descends onto a goal below it, as in exp1, from 0.12 m; a radius
    of 0.13 m in every direction drove its tool under moving goal covers. At or below
    ``radius`` it changes nothing."""
    axial_angle: float = math.radians(15.0)
    """Largest angle, rad, between the tool's axis and the path for ``axial_radius``."""
    margin: float = 0.01
    """Least clearance, m, between the tool's surface on the straight path and anything a ray
    sees. Testing the path rather than every ray lets the tool pass beside a wall next to
    the goal."""
    ee_step: float = 0.005
    """The robot's largest translation per action, m."""
    rot_step: float = 0.005
    """The robot's largest rotation per action, rad."""
    tool_length: float = 0.0
    """Length of the cylindrical tool behind the end effector, m (0: the tip alone)."""
    tool_radius: float = 0.0
    """Radius of that tool, m."""
    stall_steps: int = 0
    """When the last this many steps brought the end effector less than ``stall_gain``
    nearer the goal, step towards it instead of the policy (through the safety layer), from
    any distance, until they have: a nudge of about ``stall_gain``, after which the policy
    acts again from a new state. The mean action of a policy that hovers or presses against
    what it sees repeats itself until the step budget runs out. 0 (the default): off. At 100
    the shipped policies succeed more often and collide more often too, since the nudges go
    where no ray looks (docs/acting.md), so it is the user's choice."""
    stall_gain: float = 0.01
    """Least progress towards the goal, m, over ``stall_steps`` steps."""
    turn: bool = True
    """Where the tip's own path (the tool's radius around it) keeps the margin and only the
    tool behind it does not, turn the tool about its tip, one rotation step at a time,
    towards the path, while the turned tool keeps the margin or comes no nearer to anything
    seen. A tool pointing along its path sweeps only the path. A KR16 tool tilted across an
    upright plate beside the goal swept its back over the plate's edge, so the path was
    refused again and again and the run timed out (docs/acting.md)."""
    give_way: bool = True
    """Once a veto (the arm's rule, the shield) has held one of its steps and every shorter
    share of it, leave the goal to the policy until the next goal. The straight path is
    tested against the tool alone: into a shelf's compartment it can lead the wrist onto a
    board, where the arm's rule holds the arm, step after step, until the budget runs out,
    although the policy alone would have reached the goal (docs/acting.md)."""

    def __post_init__(self) -> None:
        for name in ("radius", "axial_radius", "axial_angle", "ee_step", "rot_step", "stall_gain"):
            if getattr(self, name) is not None and not getattr(self, name) > 0:
                raise ValueError(f"{name} must be positive, got {getattr(self, name)}")
        for name in ("margin", "tool_length", "tool_radius", "stall_steps"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)}")
        if not isinstance(self.stall_steps, (int, np.integer)):
            raise ValueError(f"stall_steps must be a whole number of steps, got {self.stall_steps}")

    def stalled(self, distances: Sequence[float]) -> bool:
        """Whether ``distances`` (to the current goal after each step, oldest first) show a
        stall: ``stall_steps`` steps that brought the end effector less than ``stall_gain``
        nearer."""
        return self.stall_steps > 0 and stalled(distances, self.stall_steps, self.stall_gain)

    @staticmethod
    def towards(goal_offset: np.ndarray) -> np.ndarray:
        """A full step along ``goal_offset`` (goal minus end effector, m), as an action (also the
        safety layer's slide, ``rayreach.acting.layers``)."""
        action = np.zeros(6, dtype=np.float32)
        action[:3] = np.asarray(goal_offset, dtype=float) / max(float(np.linalg.norm(goal_offset)), 1e-9)
        return action

    def action(self, goal_offset: np.ndarray, hits: np.ndarray,
               tool_direction: np.ndarray | None = None) -> np.ndarray | None:
        """The straight step along ``goal_offset`` (goal minus end effector, m), or None to
        leave it to the policy. ``hits``: the points the rays see, relative to the end
        effector, shape (n, 3). ``tool_direction``: unit vector from the flange to the tip
        (None: the tip alone, with ``tool_radius`` around it); the tool's axis sweeps a
        parallelogram along the path, which every hit must clear by ``tool_radius + margin``,
        unless one hit is that near already and the path brings the tool no nearer to any
        hit than to that one now (a wall it slides along, a compartment it reaches into).
        A hit within ``NEARER`` of the tool (contact) therefore no longer blocks the path;
        the safety layer's ray shield still does. Where the path is refused, the step may be
        a turn of the tool instead (``turn``): a rotation and no translation."""
        if self.radius is None:
            raise ValueError("FinalApproach.radius is None: give one, or let ActingEnv fill in the robot's")
        goal_offset = np.asarray(goal_offset, dtype=float)
        if not self.within_reach(goal_offset, tool_direction):
            return None
        if len(hits):
            hits = np.asarray(hits, dtype=float)
            back = np.zeros(3) if tool_direction is None else -self.tool_length * np.asarray(tool_direction, float)
            on_path = distances_to_parallelogram(hits, goal_offset, back).min()
            if on_path < self.tool_radius + self.margin:
                now = distances_to_segment(hits, np.zeros(3), back).min()  # the tool where it is
                if on_path < now - self.NEARER:
                    return self._turn(goal_offset, hits, tool_direction, now) if self.turn else None
        # along the path tested, not clipped axis by axis: a goal 10 cm below and 1 cm aside
        # took steps of 5 mm down and 5 mm aside, towards a wall beside the goal
        action = np.zeros(6, dtype=np.float32)
        action[:3] = goal_offset / max(float(np.abs(goal_offset).max()), self.ee_step)
        return action

    def within_reach(self, goal_offset: np.ndarray, tool_direction: np.ndarray | None = None) -> bool:
        """Whether the goal, ``goal_offset`` (m) from the end effector, is near enough to step
        straight at: within ``radius``, or within ``axial_radius`` along the tool's axis."""
        distance = float(np.linalg.norm(goal_offset))
        if distance < self.radius:  # type: ignore[operator]
            return True
        if self.axial_radius is None or tool_direction is None or distance >= self.axial_radius:
            return False
        along = float(np.asarray(goal_offset, float) @ np.asarray(tool_direction, float))
        return along > distance * math.cos(self.axial_angle)

    def _turn(self, goal_offset: np.ndarray, hits: np.ndarray, tool_direction: np.ndarray | None,
              now: float) -> np.ndarray | None:
        """One rotation step of the tool about its tip towards ``goal_offset``, as an action;
        None where the tip's own path is refused too, the tool points along the path
        already, or the turned tool would come within the margin of a hit and nearer to it
        than the tool is now to any (``now``)."""
        length = float(np.linalg.norm(goal_offset))
        if tool_direction is None or not length > 0:
            return None
        need = self.tool_radius + self.margin
        if distances_to_segment(hits, np.zeros(3), goal_offset).min() < need:
            return None
        tool, path = np.asarray(tool_direction, dtype=float), goal_offset / length
        axis = np.cross(tool, path)
        size = float(np.linalg.norm(axis))
        angle = float(np.arctan2(size, tool @ path))
        if angle < self.TURNED or size < 1e-12:
            return None
        rotation = axis / size * min(angle, self.rot_step)
        turned = rotvec_to_matrix(rotation) @ tool
        after = distances_to_segment(hits, np.zeros(3), -self.tool_length * turned).min()
        if after < need and after < now:  # no allowance: turn after turn would creep nearer
            return None
        action = np.zeros(6, dtype=np.float32)
        action[3:] = rotation / self.rot_step
        return action


def stalled(distances: Sequence[float], steps: int, gain: float) -> bool:
    """Whether ``distances`` (to the current goal after each step, oldest first) hold ``steps``
    steps (>= 1) and the last ``steps`` of them brought the end effector less than ``gain``
    nearer."""
    return len(distances) > steps and distances[-steps - 1] - distances[-1] < gain
