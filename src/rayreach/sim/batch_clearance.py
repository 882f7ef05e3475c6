"""What only a simulator knows about N worlds: how near each part of the arm is to the
obstacles, and how those obstacles move. A privileged teacher's observation
(``ObservationConfig.privileged``), never a deployed policy's.

For each of the arm's collision spheres (``batch_collision.ArmSpheres``) the nearest point of
any obstacle's surface is found, compiled, for every world:

* ``near`` (3): the unit vector from the sphere's centre towards that point, times
  ``1 - gap / reach`` (``gap``: the distance from the sphere's surface, clipped to
  [0, ``reach``]), so it points at the obstacle and grows as it comes closer, and is zero
  beyond ``reach``;
* ``motion`` (3): that obstacle's velocity over ``SPEED_SCALE``, zero beyond ``reach``.

Both are in the end effector's frame, as a policy would want them wherever the arm stands.
``tests/test_batch_clearance.py`` holds the gaps to PyBullet's ``getClosestPoints``.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from rayreach.sim.batch_collision import ArmSpheres, _place
from rayreach.sim.batch_obstacles import ObstacleBatch

PER_SPHERE = 6
"""Values per arm sphere: ``near`` (3), then ``motion`` (3)."""
REACH = 0.3
"""Gaps beyond this, m, read as nothing near (the paper's rays reach 0.4 m from the arm's surface)."""
SPEED_SCALE = 0.2
"""Obstacle speeds in units of this, m/s: the random worlds' fastest plates move at 0.2 m/s."""


def clearance(frames: np.ndarray, spheres: ArmSpheres, obstacles: ObstacleBatch, time: np.ndarray,
              ee_rot: np.ndarray, which: np.ndarray, out: np.ndarray, reach: float = REACH) -> None:
    """Rows ``which`` of ``out`` (N, K * PER_SPHERE): each world's values for its DH ``frames``
    (N, 7, 4, 4), obstacles where they are now, ``time`` (N,) s into the episode (for the
    direction a back-and-forth obstacle goes) and end-effector rotations ``ee_rot`` (N, 3, 3)."""
    b, s, arm = obstacles.boxes, obstacles.spheres, spheres
    _clearance(frames, arm.frame, arm.centre, arm.radius, b.pos, b.rot, b.size, b.count, b.direction, b.speed,
               b.travel, s.pos, s.size, s.count, s.direction, s.speed, s.travel, time, ee_rot,
               np.asarray(which, dtype=np.int64), float(reach), out)


def gaps(frames: np.ndarray, spheres: ArmSpheres, obstacles: ObstacleBatch) -> np.ndarray:
    """(N, K) distance, m, from each arm sphere's surface to the nearest obstacle (negative:
    overlapping; inf: no obstacle): what ``clearance`` encodes, for tests and plots."""
    n = len(frames)
    out = np.empty((n, len(spheres.frame)))
    b, s = obstacles.boxes, obstacles.spheres
    _gaps(frames, spheres.frame, spheres.centre, spheres.radius, b.pos, b.rot, b.size, b.count, s.pos, s.size,
          s.count, out)
    return out


@numba.njit(cache=True)
def _nearest_box(c, pos, rot, half, point):  # pragma: no cover - compiled
    """Distance from ``c`` to a box (0 inside), its nearest point into ``point``."""
    local = np.empty(3)
    for r in range(3):
        local[r] = rot[0, r] * (c[0] - pos[0]) + rot[1, r] * (c[1] - pos[1]) + rot[2, r] * (c[2] - pos[2])
        local[r] = min(max(local[r], -half[r]), half[r])
    for r in range(3):
        point[r] = pos[r] + rot[r, 0] * local[0] + rot[r, 1] * local[1] + rot[r, 2] * local[2]
    return math.sqrt((c[0] - point[0]) ** 2 + (c[1] - point[1]) ** 2 + (c[2] - point[2]) ** 2)


@numba.njit(cache=True)
def _nearest_ball(c, pos, radius, point):  # pragma: no cover - compiled
    """Distance from ``c`` to a ball's surface (0 inside), its nearest point into ``point``."""
    d = math.sqrt((c[0] - pos[0]) ** 2 + (c[1] - pos[1]) ** 2 + (c[2] - pos[2]) ** 2)
    if d <= radius:
        for r in range(3):
            point[r] = c[r]
        return 0.0
    for r in range(3):
        point[r] = pos[r] + (c[r] - pos[r]) * radius / d
    return d - radius


@numba.njit(cache=True)
def _leg_sign(speed, travel, t):  # pragma: no cover - compiled
    """+1 while a back-and-forth obstacle goes out, -1 on its way back (``ObstacleBatch._move``)."""
    if travel <= 0.0:
        return 1.0
    return 1.0 if (speed * t) % (2.0 * travel) <= travel else -1.0


@numba.njit(cache=True)
def _keep(point, direction, speed, travel, t, best, vel):  # pragma: no cover - compiled
    """The nearest obstacle so far: its point into ``best``, its velocity now into ``vel``."""
    sign = _leg_sign(speed, travel, t)
    for r in range(3):
        best[r] = point[r]
        vel[r] = direction[r] * speed * sign


@numba.njit(cache=True)
def _clearance(frames, frame, centre, radius, box_pos, box_rot, box_half, n_box, box_dir, box_speed, box_travel,
               ball_pos, ball_radius, n_ball, ball_dir, ball_speed, ball_travel, time, ee_rot, which, reach,
               out):  # pragma: no cover - compiled
    k_spheres = len(frame)
    world = np.empty((k_spheres, 3))
    point = np.empty(3)
    best = np.empty(3)
    vel = np.empty(3)
    for i in which:
        _place(frames[i], frame, centre, world)
        rot = ee_rot[i]
        for k in range(k_spheres):
            c = world[k]
            nearest = np.inf
            for r in range(3):
                vel[r] = 0.0
            for j in range(n_box[i]):
                d = _nearest_box(c, box_pos[i, j], box_rot[i, j], box_half[i, j], point)
                if d < nearest:
                    nearest = d
                    _keep(point, box_dir[i, j], box_speed[i, j], box_travel[i, j], time[i], best, vel)
            for j in range(n_ball[i]):
                d = _nearest_ball(c, ball_pos[i, j], ball_radius[i, j, 0], point)
                if d < nearest:
                    nearest = d
                    _keep(point, ball_dir[i, j], ball_speed[i, j], ball_travel[i, j], time[i], best, vel)
            row = k * 6
            gap = nearest - radius[k]
            if gap >= reach:
                for r in range(6):
                    out[i, row + r] = 0.0
                continue
            weight = 1.0 - max(gap, 0.0) / reach
            norm = nearest if nearest > 1e-9 else 1.0
            for r in range(3):  # world -> end-effector frame: rot.T @ v
                u = (rot[0, r] * (best[0] - c[0]) + rot[1, r] * (best[1] - c[1]) + rot[2, r] * (best[2] - c[2]))
                out[i, row + r] = weight * u / norm
                out[i, row + 3 + r] = (rot[0, r] * vel[0] + rot[1, r] * vel[1] + rot[2, r] * vel[2]) / SPEED_SCALE


@numba.njit(cache=True)
def _gaps(frames, frame, centre, radius, box_pos, box_rot, box_half, n_box, ball_pos, ball_radius, n_ball,
          out):  # pragma: no cover - compiled
    world = np.empty((len(frame), 3))
    point = np.empty(3)
    for i in range(frames.shape[0]):
        _place(frames[i], frame, centre, world)
        for k in range(len(frame)):
            nearest = np.inf
            for j in range(n_box[i]):
                nearest = min(nearest, _nearest_box(world[k], box_pos[i, j], box_rot[i, j], box_half[i, j], point))
            for j in range(n_ball[i]):
                nearest = min(nearest, _nearest_ball(world[k], ball_pos[i, j], ball_radius[i, j, 0], point))
            out[i, k] = nearest - radius[k]
