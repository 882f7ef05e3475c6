"""Typed robot descriptions: everything rayreach needs to know about an arm is data here."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np


@dataclass(frozen=True)
class DHTable:
    """Standard Denavit-Hartenberg parameters (paper eqs. 1-2), one entry per joint.

    The joint angle that enters the DH matrix is ``theta_i = sign_i * q_i + offset_i``:
    ``sign`` absorbs URDF joints whose axis points along -z of the DH frame (the KR16's
    a1, a4 and a6) and ``offset`` the zero-position difference, so ``q`` is always the
    URDF/PyBullet joint value.
    """

    d: tuple[float, ...]
    a: tuple[float, ...]
    alpha: tuple[float, ...]
    offset: tuple[float, ...] = (0.0,) * 6
    sign: tuple[float, ...] = (1.0,) * 6

    def __post_init__(self) -> None:
        n = len(self.d)
        for name in ("a", "alpha", "offset", "sign"):
            if len(getattr(self, name)) != n:
                raise ValueError(f"DH table: '{name}' has {len(getattr(self, name))} entries, 'd' has {n}")


@dataclass(frozen=True)
class SensorMount:
    """Where a ray sensor sits: a chain frame index (0 = base, 6 = flange) and a fixed offset.

    ``link`` names the URDF link the mount belongs to, for people and for the consistency
    test; the pose itself is computed from the joint chain, never from PyBullet.
    """

    link: str
    frame: int
    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    length: float | None = None
    """For a mount of rings along an arm link (``rayreach.sim.sensors.arm_layout``): how far the
    link runs along the mount's z axis, m; None for a mount of one sensor."""


@dataclass(frozen=True)
class ToolSpec:
    """A cylindrical tool (a torch) along the flange's z axis; its tip is the end effector."""

    length: float
    radius: float


@dataclass(frozen=True)
class RobotSpec:
    """A 6-axis arm: URDF source, joints, limits, base and tool frames, sensor mounts, and the
    training workspace; the kinematics come from the URDF (or, for the paper's two, a DH table).

    Adding a robot means writing one of these (see ``robots/ur10.py``).
    """

    name: str
    urdf: Callable[[], Path]
    """Returns the package's original URDF (with ``package://`` mesh paths)."""
    package_dirs: Callable[[], dict[str, Path]]
    """Maps each ``package://NAME`` prefix of the URDF to a directory on disk."""
    joint_names: tuple[str, ...]
    lower: tuple[float, ...]
    upper: tuple[float, ...]
    velocity: tuple[float, ...]
    """Joint velocity limits in rad/s (from the URDF)."""
    flange_link: str
    """URDF link at the end of the chain (the tool flange, ``tool0``); with a DH table, the link
    whose frame equals the last DH frame."""
    tool: ToolSpec
    home: tuple[float, ...]
    """A collision-free, well-conditioned configuration used to seed IK."""
    base_link: str | None = None
    """URDF link the chain starts from (frame 0), placed at ``base_position``/``base_rpy``
    through the fixed joints above it; None: the URDF's root link."""
    dh: DHTable | None = None
    """The paper's DH chain (eqs. 1-2); None: the kinematics come from the URDF's joints from
    ``base_link`` to ``flange_link`` (``rayreach.robots.chain``)."""
    dh_base_rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """With ``dh``: fixed rotation from the URDF root link to DH frame 0 (the one documented
    DH-URDF transform)."""
    base_position: tuple[float, float, float] = (0.0, 0.0, 0.0)
    base_rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    mounts: dict[str, SensorMount] = field(default_factory=dict)
    workspace_low: tuple[float, float, float] = (-0.5, -0.5, 0.0)
    workspace_high: tuple[float, float, float] = (0.5, 0.5, 1.0)
    """Default workspace bounds (world frame) for random training worlds."""
    tool_rpy: tuple[float, float, float] = (math.pi, 0.0, math.pi)
    """Default tool orientation (world roll-pitch-yaw) for random start poses."""
    training_kinds: tuple[str, ...] = ("plate", "moving_plate", "box", "sphere", "goal_cover", "goal_wall", "goal_slot")
    """Obstacle kinds of random training worlds (see ``scenarios.random_world.KINDS``)."""
    task_obstacles: int = 2
    """Obstacles per random world of the robot's task: where its policy is measured and
    where a training run picks its best checkpoint (``rayreach.learning.selection``)."""
    ee_step: float = 0.005
    """Largest end-effector translation per action, m (paper: 0.005 for both robots)."""
    rot_step: float = 0.005
    """Largest end-effector rotation per action, rad."""
    blind_links: tuple[str, ...] = ()
    """Arm links next to the tool that carry no rays and pass close to what the tool sees;
    the safety layer's arm rule keeps them clear of the points the rays hit
    (``SafetyLayer.arm_clearance``, ``rayreach.acting.arm_guard``)."""

    @property
    def n_joints(self) -> int:
        return len(self.joint_names)

    @property
    def lower_array(self) -> np.ndarray:
        return np.asarray(self.lower, dtype=float)

    @property
    def upper_array(self) -> np.ndarray:
        return np.asarray(self.upper, dtype=float)
