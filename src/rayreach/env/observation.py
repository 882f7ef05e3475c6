"""What a policy sees beyond the paper's 142 values: the goal's direction, the workspace's
walls, its own motion, and what the rays saw a moment ago.

The paper's observation (``ObservationConfig()``, every part off) tells a policy where the
goal is and what is within 0.4 m now. Two things it lacks cost most of a memoryless
policy's failures: the workspace's bounds, which no ray sees (leaving the workspace was the
first policies' commonest failure alone, docs/log/2026-12-01-policy-alone.md), and what the
arm passed a moment ago, behind rays that no longer see it (two worlds alike now but unlike
a second ago ask for unlike actions; without the remembered scans collisions rose from 26 to
44 % of validation worlds, docs/training.md, "One change at a time").
``ObservationConfig.planner()`` adds both, with the goal's direction at any distance (the
goal offset in metres, normalised by its spread over the workspace, hardly changes over the
last centimetre).

``Observer`` appends the parts to the paper's values for N worlds at once; ``ReachEnv`` uses
one with N = 1, ``BatchedReachEnv`` one with N worlds, so both give the same observation.
Appended, in this order, after the paper's 142 values:

===================  ======  =============================================================
goal_direction       6       unit vector to the goal, then the goal offset over ``NEAR``
                             clipped to [-1, 1] (world frame)
workspace            6       end effector minus the workspace's low corner, then its high
                             corner minus the end effector, m, at most ``WALL_RANGE``
motion               3       the end effector's last step, in units of the action's ``ee_step``
scans x (129 + 3)    each    a ray scan of ``scan_stride`` x (k + 1) steps ago (k = 0, 1, ..):
                             its 129 fractions, then where the end effector was then minus
                             where it is now, m (the episode's first scan until it has gone by)
tip_back             24      fractions of the rays from the tool tip that look back towards
                             the arm (``rayreach.sim.sensors.tip_back_layout``), now
slanted              32      fractions of the rays slanted along the tool
                             (``rayreach.sim.sensors.slanted_layout``), now
arm_rays             64      fractions of the rays round the upper arm and the forearm
                             (``rayreach.sim.sensors.arm_layout``), now
sightings x 4        each    the nearest point any ray saw in a window of
                             ``sighting_window`` steps (k = 0: the window under way):
                             where it was seen minus where the end effector is now, over
                             ``RAY_RANGE`` and clipped to [-1, 1], then 1 if anything was seen
                             (else four zeros)
goal_sight           3       hit fractions of the rays from the tip, the tool's middle and
                             the flange towards the goal, as long as the tip is from it
                             (``rayreach.sim.goal_rays``); 1: the straight way is clear
privileged           6 per   a teacher's only (``BatchedReachEnv``): for each of the arm's
                     sphere  collision spheres, the nearest obstacle's direction and motion
                             (``rayreach.sim.batch_clearance``)
===================  ======  =============================================================
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import gymnasium as gym
import numpy as np

from rayreach.sim.goal_rays import N_GOAL_RAYS
from rayreach.sim.sensors import EXTRA_RAYS, N_RAYS, RAY_RANGE, extra_sets
from rayreach.sim.transforms import matrix_to_rpy

N_ROBOT_OBS = 13
"""The paper's values before the rays: joints, goal offset, orientation, distance."""
OBS_SIZE = N_ROBOT_OBS + N_RAYS
"""The paper's observation (``rayreach.env.reach``'s table)."""
ONE_WORLD = np.array([0])
"""The one world of an env that is not batched, as ``Observer`` indexes worlds."""
NEAR = 0.05
"""Goal offsets up to this, m, span the whole [-1, 1] of the fine offset."""
WALL_RANGE = 0.3
"""Workspace walls farther than this, m, read as this: the policy sees the walls near it, as
the rays see obstacles, and a larger user workspace looks like the training one."""
TIE = 1e-6
"""Ray fractions this close count as one distance where the nearest sighting is chosen."""
SCAN_OFFSET_RANGE = 1.0
"""Bound on a remembered scan's end-effector offset, m (for the observation space)."""


def paper_observation(q: np.ndarray, goal: np.ndarray, ee_pos: np.ndarray, ee_rot: np.ndarray,
                      ref_rot_t: np.ndarray, distance: float, rays: np.ndarray) -> np.ndarray:
    """The paper's 142 values: joints, goal minus end effector, the tool's orientation relative
    to its start (``ref_rot_t`` the start's rotation transposed) as roll-pitch-yaw, the
    distance, the ray fractions."""
    obs = np.empty(OBS_SIZE, dtype=np.float32)
    obs[0:6] = q
    obs[6:9] = goal - ee_pos
    obs[9:12] = matrix_to_rpy(ref_rot_t @ ee_rot)
    obs[12] = distance
    obs[N_ROBOT_OBS:] = rays
    return obs


@dataclass(frozen=True)
class ObservationConfig:
    """The parts of the observation beyond the paper's; all off is the paper's observation."""

    goal_direction: bool = False
    workspace: bool = False
    motion: bool = False
    scans: int = 0
    """Remembered ray scans (0: none)."""
    scan_stride: int = 8
    """Steps between remembered scans: 8 steps of at most 5 mm is up to 4 cm of travel."""
    tip_back: bool = False
    """Rays beside the paper's 129 that see what lies over the tool's tip (a plate over the
    goal); an env casts them only for a policy that has them. 9 points of validation
    success on UR5 worlds (docs/training.md, "The goal under a cover")."""
    slanted: bool = False
    """Rays beside the paper's 129, slanted along the tool, that meet a thin plate lying across
    it (docs/log/2026-12-07-levers-measured.md, "Rays slanted along the tool"); read after the
    tip-back rays."""
    arm_rays: bool = False
    """Rays beside the paper's 129 in rings round the upper arm and the forearm, which in broad
    worlds hit much of what the tool does not (docs/training.md, "What the arm hits"); read
    after the slanted rays."""
    sightings: int = 0
    """Windows of remembered sightings (0: none): the nearest point the rays saw in each, where
    it was seen. A 4 mm plate met edge-on is seen by 1 to 3 rays for a few steps and then by
    none until the tool hits it (docs/log/2026-12-05-cover-sight.md); a remembered sighting
    keeps it where it was seen, relative to the end effector's position (world axes), for
    ``sightings`` x ``sighting_window`` steps."""
    sighting_window: int = 8
    """Steps per window of sightings: 8 steps of at most 5 mm is up to 4 cm of travel."""
    goal_sight: bool = False
    """Three rays from the tool aimed at the goal (``rayreach.sim.goal_rays``): whether the
    straight way there is clear, which no ray of a fixed layout tells of a thin plate over the
    goal."""
    privileged: bool = False
    """What only the simulator knows, after everything else: how near each of the arm's
    collision spheres is to the obstacles and how they move (``rayreach.sim.batch_clearance``).
    A teacher's observation, for distillation into a policy without it (``rayreach.learning.
    distill``); only ``BatchedReachEnv`` computes it."""

    def __post_init__(self) -> None:
        if self.scans < 0:
            raise ValueError(f"scans must be >= 0, got {self.scans}")
        if self.scan_stride < 1:
            raise ValueError(f"scan_stride must be >= 1, got {self.scan_stride}")
        if self.sightings < 0:
            raise ValueError(f"sightings must be >= 0, got {self.sightings}")
        if self.sighting_window < 1:
            raise ValueError(f"sighting_window must be >= 1, got {self.sighting_window}")

    @classmethod
    def planner(cls) -> "ObservationConfig":
        """Every part on, three scans 8, 16 and 24 steps back."""
        return cls(goal_direction=True, workspace=True, motion=True, scans=3, tip_back=True)

    @property
    def is_paper(self) -> bool:
        return self.extra_size(0) == 0 and not self.privileged

    @property
    def deployable(self) -> "ObservationConfig":
        """This observation without the privileged part: what a student of a teacher sees."""
        return replace(self, privileged=False)

    def extra_size(self, n_rays: int) -> int:
        """Values appended after the paper's, for ``n_rays`` rays (the privileged part, whose
        size depends on the robot, is the env's to add)."""
        return (6 * self.goal_direction + 6 * self.workspace + 3 * self.motion + self.scans * (n_rays + 3)
                + self.extra_rays + 4 * self.sightings + N_GOAL_RAYS * self.goal_sight)

    @property
    def extra_rays(self) -> int:
        """Rays read beyond the paper's 129 (``rayreach.sim.sensors.extra_layout``)."""
        return sum(n for _, n, _ in extra_sets(self.ray_sets))

    @property
    def ray_sets(self) -> tuple[str, ...]:
        """The ``rayreach.sim.sensors.EXTRA_RAYS`` sets read beyond the paper's 129, by field name."""
        return tuple(name for name in EXTRA_RAYS if getattr(self, name))


class Observer:
    """The observation of ``n_worlds`` worlds: the paper's values, then ``config``'s parts.

    ``reset`` starts a world's memory, ``step`` adds a step to it; both write the worlds'
    rows of ``obs``, which the caller copies."""

    def __init__(self, config: ObservationConfig, n_worlds: int, n_rays: int, base_size: int,
                 ee_step: float) -> None:
        self.config = config
        self.n_rays = n_rays
        self.base_size = base_size
        self.ee_step = ee_step
        self.size = base_size + config.extra_size(n_rays)
        self.obs = np.zeros((n_worlds, self.size), dtype=np.float32)
        self.length = config.scan_stride * config.scans + 1
        """Scans kept per world: the oldest remembered one is ``length - 1`` steps back."""
        self.scan_rays = np.ones((n_worlds, self.length if config.scans else 0, n_rays))
        self.scan_ee = np.zeros((n_worlds, self.length if config.scans else 0, 3))
        self.t = np.zeros(n_worlds, dtype=np.int64)
        self.last_ee = np.zeros((n_worlds, 3))
        self.sight_point = np.zeros((n_worlds, config.sightings, 3))
        self.sight_range = np.full((n_worlds, config.sightings), np.inf)
        """Per window of sightings (a ring), the nearest point seen in it and how far it was from
        its ray's origin, m; inf: nothing seen."""

    def space(self, base: gym.spaces.Box) -> gym.spaces.Box:
        """``base`` (the paper's bounds) with the appended parts' bounds."""
        c = self.config
        low, high = [base.low], [base.high]
        if c.goal_direction:
            low.append(-np.ones(6))
            high.append(np.ones(6))
        if c.workspace:
            low.append(np.full(6, -2 * self.ee_step))
            high.append(np.full(6, WALL_RANGE))
        if c.motion:
            low.append(np.full(3, -2.0))
            high.append(np.full(3, 2.0))
        for _ in range(c.scans):
            low.append(np.concatenate((np.zeros(self.n_rays), np.full(3, -SCAN_OFFSET_RANGE))))
            high.append(np.concatenate((np.ones(self.n_rays), np.full(3, SCAN_OFFSET_RANGE))))
        if c.extra_rays:
            low.append(np.zeros(c.extra_rays))
            high.append(np.ones(c.extra_rays))
        if c.sightings:
            low.append(np.tile([-1.0, -1.0, -1.0, 0.0], c.sightings))
            high.append(np.ones(4 * c.sightings))
        if c.goal_sight:
            low.append(np.zeros(N_GOAL_RAYS))
            high.append(np.ones(N_GOAL_RAYS))
        return gym.spaces.Box(np.concatenate(low).astype(np.float32), np.concatenate(high).astype(np.float32),
                              dtype=np.float32)

    def reset(self, which: np.ndarray, base: np.ndarray, ee: np.ndarray, rays: np.ndarray,
              ws_low: np.ndarray, ws_high: np.ndarray, extra: np.ndarray | None = None,
              nearest: tuple[np.ndarray, np.ndarray] | None = None, goal_clear: np.ndarray | None = None) -> None:
        """Worlds ``which`` start an episode: their memory holds only this moment.
        ``extra``: their fractions of the rays beyond the 129, where the config has them;
        ``nearest``: their nearest sighting now (``nearest_sightings``), where it has sightings;
        ``goal_clear``: their goal rays' fractions (``rayreach.sim.goal_rays``), where it has them."""
        self.t[which] = 0
        self.last_ee[which] = ee
        if self.config.scans:
            self.scan_rays[which] = rays[:, None, :]
            self.scan_ee[which] = ee[:, None, :]
        if self.config.sightings:
            self.sight_range[which] = np.inf
        self._write(which, base, ee, rays, ws_low, ws_high, extra, nearest, goal_clear)

    def step(self, which: np.ndarray, base: np.ndarray, ee: np.ndarray, rays: np.ndarray,
             ws_low: np.ndarray, ws_high: np.ndarray, extra: np.ndarray | None = None,
             nearest: tuple[np.ndarray, np.ndarray] | None = None, goal_clear: np.ndarray | None = None) -> None:
        """Worlds ``which`` took a step; ``base`` is their paper observation after it."""
        self.t[which] += 1
        if self.config.scans:
            slot = self.t[which] % self.length
            self.scan_rays[which, slot] = rays
            self.scan_ee[which, slot] = ee
        self._write(which, base, ee, rays, ws_low, ws_high, extra, nearest, goal_clear)
        self.last_ee[which] = ee

    def _write(self, which, base, ee, rays, ws_low, ws_high, extra, nearest, goal_clear) -> None:
        c, out = self.config, self.obs
        out[which, : self.base_size] = base
        k = self.base_size
        if c.goal_direction:
            offset = base[:, 6:9].astype(float)
            distance = np.maximum(np.linalg.norm(offset, axis=1, keepdims=True), 1e-9)
            out[which, k: k + 3] = offset / distance
            out[which, k + 3: k + 6] = np.clip(offset / NEAR, -1.0, 1.0)
            k += 6
        if c.workspace:
            out[which, k: k + 3] = np.minimum(ee - ws_low, WALL_RANGE)
            out[which, k + 3: k + 6] = np.minimum(ws_high - ee, WALL_RANGE)
            k += 6
        if c.motion:
            out[which, k: k + 3] = np.clip((ee - self.last_ee[which]) / self.ee_step, -2.0, 2.0)
            k += 3
        for back in range(c.scans):
            slot = (self.t[which] - c.scan_stride * (back + 1)) % self.length
            out[which, k: k + self.n_rays] = self.scan_rays[which, slot]
            out[which, k + self.n_rays: k + self.n_rays + 3] = np.clip(
                self.scan_ee[which, slot] - ee, -SCAN_OFFSET_RANGE, SCAN_OFFSET_RANGE)
            k += self.n_rays + 3
        if c.extra_rays:
            if extra is None:
                raise ValueError(f"this observation holds {c.extra_rays} rays beyond the 129 (ObservationConfig."
                                 "tip_back, slanted, arm_rays); pass their fractions")
            out[which, k: k + c.extra_rays] = extra
            k += c.extra_rays
        if c.sightings:
            if nearest is None:
                raise ValueError(f"this observation remembers {c.sightings} windows of sightings (ObservationConfig."
                                 "sightings); pass the nearest sighting of each world")
            out[which, k: k + 4 * c.sightings] = self._sightings(which, ee, *nearest)
            k += 4 * c.sightings
        if c.goal_sight:
            if goal_clear is None:
                raise ValueError("this observation holds the goal rays (ObservationConfig.goal_sight); pass their "
                                 "fractions")
            out[which, k: k + N_GOAL_RAYS] = goal_clear

    def _sightings(self, which: np.ndarray, ee: np.ndarray, point: np.ndarray, reach: np.ndarray) -> np.ndarray:
        """Worlds ``which``'s sightings part, with this step's nearest sighting kept first.

        Windows are blocks of the episode's steps (0 to w - 1, w to 2w - 1, ...), each holding
        its nearest sighting so far; the latest is the one under way."""
        c = self.config
        t = self.t[which]
        block = (t // c.sighting_window) % c.sightings
        fresh = t % c.sighting_window == 0  # a block starts: what its slot held has gone by
        self.sight_range[which[fresh], block[fresh]] = np.inf
        nearer = reach < self.sight_range[which, block] - TIE * RAY_RANGE  # a tie keeps the earlier
        self.sight_range[which[nearer], block[nearer]] = reach[nearer]
        self.sight_point[which[nearer], block[nearer]] = point[nearer]
        order = (t[:, None] // c.sighting_window - np.arange(c.sightings)) % c.sightings  # newest first
        seen = self.sight_range[which[:, None], order] < np.inf
        offset = np.clip((self.sight_point[which[:, None], order] - ee[:, None, :]) / RAY_RANGE, -1.0, 1.0)
        return np.concatenate((offset * seen[:, :, None], seen[:, :, None]), axis=2).reshape(len(which), -1)


def nearest_ray(fractions: np.ndarray) -> np.ndarray:
    """Per world, the ray whose hit lies nearest its origin: of rays within ``TIE`` of the
    nearest (a ring meeting a plate square to it), the first, so that casters that round
    alike to ``TIE`` pick the same ray. ``fractions`` (n, k)."""
    return (fractions <= fractions.min(axis=1, keepdims=True) + TIE).argmax(axis=1)


def nearest_sightings(fractions: np.ndarray, origins: np.ndarray, directions: np.ndarray,
                      ray_range: float) -> tuple[np.ndarray, np.ndarray]:
    """Per world, the nearest point its rays see and how far along its ray it lies, m (inf
    where nothing is seen): ``fractions`` (n, k), ``origins`` and ``directions`` (n, k, 3)."""
    best = nearest_ray(fractions)
    fraction = np.take_along_axis(fractions, best[:, None], axis=1)[:, 0]
    reach = fraction * ray_range
    rows = np.arange(len(best))
    point = origins[rows, best] + directions[rows, best] * reach[:, None]
    return point, np.where(fraction < 1.0, reach, np.inf)


def one_world_sighting(ray_range: float, *ray_sets: tuple[np.ndarray, np.ndarray, np.ndarray]
                       ) -> tuple[np.ndarray, np.ndarray]:
    """One world's ``nearest_sightings`` over the ray sets it reads, each (origins (k, 3),
    directions (k, 3), fractions (k,)), in observation order: the 129, then those beyond."""
    origins, directions, fractions = (np.concatenate(parts) for parts in zip(*ray_sets))
    return nearest_sightings(fractions[None], origins[None], directions[None], ray_range)
