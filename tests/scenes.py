"""Constructed scenes for the tests."""

from __future__ import annotations

import numpy as np


def plate_over_the_tip(back: float, centre_out: float, half: float):
    """UR5 at its home joints with a flat plate ``back`` m up the tool from its tip, square
    to the tool's axis, its centre ``centre_out`` m out along the tool frame's x (a plate
    just over the goal, as a goal-cover world has it)."""
    from rayreach.robots import get_robot
    from rayreach.scenarios.random_world import drawn_scenario
    from rayreach.scenarios.schema import ObstacleSpec
    from rayreach.sim.kinematics import Kinematics
    from rayreach.sim.transforms import matrix_to_rpy

    spec = get_robot("ur5")
    tip = Kinematics(spec).fk(np.asarray(spec.home))
    axis, out = tip[:3, 2], tip[:3, 0]
    centre = tip[:3, 3] - back * axis + centre_out * out
    plate = ObstacleSpec("box", tuple(centre), rpy=tuple(matrix_to_rpy(tip[:3, :3])), half_extents=(half, half, 0.002),
                         name="plate_0")
    return drawn_scenario("plate", "ur5", np.asarray(spec.home), tip[:3, 3] + 0.3 * out, [plate],
                          spec.workspace_low, spec.workspace_high, "a plate over the tool's tip")


def wall_before_the_goal(wall_at: float, goal_out: float, reach_up: float):
    """UR5 at its home joints; the goal ``goal_out`` m out along the tool frame's x; a wall
    4 mm thick square to that way, its near face ``wall_at`` m out, reaching ``reach_up`` m up
    the tool from the tip's height (and as far below it)."""
    from rayreach.robots import get_robot
    from rayreach.scenarios.random_world import drawn_scenario
    from rayreach.scenarios.schema import ObstacleSpec
    from rayreach.sim.kinematics import Kinematics
    from rayreach.sim.transforms import matrix_to_rpy

    spec = get_robot("ur5")
    tip = Kinematics(spec).fk(np.asarray(spec.home))
    out = tip[:3, 0]
    wall = ObstacleSpec("box", tuple(tip[:3, 3] + (wall_at + 0.002) * out),
                        rpy=tuple(matrix_to_rpy(tip[:3, :3])), half_extents=(0.002, 0.1, reach_up), name="wall_0")
    return drawn_scenario("wall", "ur5", np.asarray(spec.home), tip[:3, 3] + goal_out * out, [wall],
                          spec.workspace_low, spec.workspace_high, "a wall between the tip and the goal")


def box_beside_the_forearm(gap: float, along: float = 0.5, side: float = 1.0):
    """UR5 at its home joints with a box whose near face lies ``gap`` m from the forearm's
    axis, its middle ``along`` the forearm's length from the wrist, square to the forearm
    mount's y axis (``side`` +1: the way its rays of azimuth 90 deg leave it, -1: 270 deg),
    0.1 m wide, 0.2 m long along the forearm; the goal 0.3 m out along the tool frame's x."""
    from rayreach.robots import get_robot
    from rayreach.scenarios.random_world import drawn_scenario
    from rayreach.scenarios.schema import ObstacleSpec
    from rayreach.sim.kinematics import Kinematics
    from rayreach.sim.sensors import mount_offset
    from rayreach.sim.transforms import matrix_to_rpy

    spec = get_robot("ur5")
    kin = Kinematics(spec)
    mount = spec.mounts["forearm"]
    pose = kin.frames(np.asarray(spec.home))[mount.frame] @ mount_offset(mount)
    side, axis = side * pose[:3, 1], pose[:3, 2]
    half = 0.05
    centre = pose[:3, 3] + along * mount.length * axis + (gap + half) * side
    box = ObstacleSpec("box", tuple(centre), rpy=tuple(matrix_to_rpy(pose[:3, :3])), half_extents=(half, half, 0.1),
                       name="box_0")
    tip = kin.fk(np.asarray(spec.home))
    return drawn_scenario("box", "ur5", np.asarray(spec.home), tip[:3, 3] + 0.3 * tip[:3, 0], [box],
                          spec.workspace_low, spec.workspace_high, "a box beside the forearm")


def on_the_box(points: np.ndarray, box) -> np.ndarray:
    """Which of ``points`` (n, 3) lie in or on the box obstacle ``box`` (an ``ObstacleSpec``)."""
    import pybullet as p

    rot = np.asarray(p.getMatrixFromQuaternion(p.getQuaternionFromEuler(box.rpy))).reshape(3, 3)
    local = (points - np.asarray(box.position)) @ rot
    return np.all(np.abs(local) <= np.asarray(box.half_extents) + 1e-6, axis=1)


def elbow_step_towards(kin, q: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """A 0.05 rad joint step of the elbow alone that brings the forearm's wrist end nearer
    ``centre``."""
    toward = np.zeros(6)
    toward[2] = 0.05
    wrist_end = kin.frames(q)[3][:3, 3]
    if np.linalg.norm(kin.frames(q + toward)[3][:3, 3] - centre) > np.linalg.norm(wrist_end - centre):
        toward = -toward
    return toward
