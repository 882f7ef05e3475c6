"""Virtual laser sensors (paper section "Observation Space"): ray layouts and ray casting.

The 129 rays, in observation order:

====  ======  ===========  ===========================================================
from  count   sensor       layout (in the mount frame, z = the tool's pointing axis)
====  ======  ===========  ===========================================================
0     24      wrist        2 cones of 12 rays, 30 deg apart around z, polar angle 40 deg:
                           first the cone opening along +z (towards the work), then the
                           one along -z (back towards the arm); origin on the tool axis
                           behind the flange
24    80      wraparound   8 columns 45 deg apart around the tool, 10 rays each, radial
                           (perpendicular to the tool), origins on the tool's surface,
                           evenly spaced along it; column-major (azimuth, then height
                           from flange to tip)
104   25      tip          1 ray along +z, then 2 rings of 12 rays 30 deg apart at polar
                           angles 20 and 40 deg, origin at the tool tip
====  ======  ===========  ===========================================================

Beyond the 129, ``EXTRA_RAYS`` lists the sets an observation may read after them: rays from
the tip back towards the arm, rays slanted along the tool, and rings round the upper arm and
the forearm.

Each ray reports its hit fraction in [0, 1] over ``RAY_RANGE`` (1 = nothing within range).
The robot (arm and tool) is invisible to the rays.

Two casting backends share one interface: :class:`NumpyCaster` (analytic intersection with
boxes, spheres and cylinders, vectorised; the default when every obstacle is a primitive)
and :class:`BulletCaster` (PyBullet ``rayTestBatch``, the reference, works with any mesh).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Iterable, Protocol

import numpy as np

from rayreach.robots.spec import RobotSpec, SensorMount
from rayreach.sim.transforms import pose_matrix, rpy_to_matrix

RAY_RANGE = 0.4
"""Sensor range in metres (paper: 0.4 m for every sensor)."""
N_RAYS = 129
SENSOR_SLICES = {"wrist": slice(0, 24), "wraparound": slice(24, 104), "tip": slice(104, 129)}
TIP_BACK_POLAR = (110.0, 135.0)
"""Polar angles from the tool's axis, deg, of the two rings of ``tip_back_layout``."""
N_TIP_BACK = 12 * len(TIP_BACK_POLAR)
SLANTED_TILT = 45.0
"""Tilt of the slanted rays from the wraparound's radial directions towards the flange and the
tip, deg."""
SLANTED_HEIGHTS = (0.25, 0.75)
"""Where along the tool the slanted rays start, as shares of its length from the flange."""
N_SLANTED = 8 * len(SLANTED_HEIGHTS) * 2
ARM_MOUNTS = ("upper_arm", "forearm")
"""The links ``arm_layout`` rings with rays, by their ``RobotSpec.mounts`` name."""
ARM_STATIONS = 4
"""Rings of rays along each of ``ARM_MOUNTS``, at the middles of equal parts of its length."""
ARM_AZIMUTHS = 8
N_ARM = len(ARM_MOUNTS) * ARM_STATIONS * ARM_AZIMUTHS


@dataclass(frozen=True)
class RayGroup:
    """Rays fixed in one mount frame: local origins and unit directions, shape (n, 3)."""

    mount: str
    origins: np.ndarray
    directions: np.ndarray


def _cone(polar_deg: float, n_azimuth: int, step_deg: float, axis_sign: float = 1.0) -> np.ndarray:
    polar = math.radians(polar_deg)
    az = np.radians(np.arange(n_azimuth) * step_deg)
    s = math.sin(polar)
    return np.stack((s * np.cos(az), s * np.sin(az), np.full(n_azimuth, axis_sign * math.cos(polar))), axis=1)


def ray_layout(spec: RobotSpec) -> list[RayGroup]:
    """The paper's three sensors for a robot, in observation order (see the module table)."""
    length, radius = spec.tool.length, spec.tool.radius
    wrist_dirs = np.concatenate((_cone(40, 12, 30, +1.0), _cone(40, 12, 30, -1.0)))
    wrist = RayGroup("wrist", np.zeros((24, 3)), wrist_dirs)

    az = np.radians(np.arange(8) * 45.0)
    heights = (np.arange(10) + 0.5) * length / 10.0
    radial = np.stack((np.cos(az), np.sin(az), np.zeros(8)), axis=1)
    wrap_dirs = np.repeat(radial, 10, axis=0)
    wrap_origins = wrap_dirs * radius + np.stack(
        (np.zeros(80), np.zeros(80), np.tile(heights, 8)), axis=1
    )
    wrap = RayGroup("tool", wrap_origins, wrap_dirs)

    tip_dirs = np.concatenate(([[0.0, 0.0, 1.0]], _cone(20, 12, 30), _cone(40, 12, 30)))
    tip = RayGroup("tool", np.tile([0.0, 0.0, length], (25, 1)), tip_dirs)
    return [wrist, wrap, tip]


def tip_back_layout(spec: RobotSpec) -> list[RayGroup]:
    """Rays beside the paper's 129, an option of the observation
    (``ObservationConfig.tip_back``): two rings of 12 from the tool tip that open back
    towards the arm (``TIP_BACK_POLAR``). Every paper ray looks down the tool or out from
    it, so a flat plate a few centimetres over the goal lies edge-on to the wraparound rays
    (0-4 of the 104 wrist and wraparound rays saw one before the tool hit it,
    docs/training.md); these see its underside."""
    dirs = np.concatenate([_cone(polar, 12, 30) for polar in TIP_BACK_POLAR])
    return [RayGroup("tool", np.tile([0.0, 0.0, spec.tool.length], (len(dirs), 1)), dirs)]


def slanted_layout(spec: RobotSpec) -> list[RayGroup]:
    """Rays beside the paper's 129, an option of the observation (``ObservationConfig.slanted``):
    from the tool's surface at ``SLANTED_HEIGHTS``, 8 azimuths 45 deg apart as the wraparound's,
    each tilted by ``SLANTED_TILT`` towards the flange and towards the tip. The wraparound's
    radial rays are 13 mm apart along the UR5's tool, so a plate a few millimetres thick that
    lies across the tool falls between them; a slanted ray meets it along its whole length.
    Order: height, then azimuth, then the tilt towards the flange before the one towards the tip."""
    length, radius = spec.tool.length, spec.tool.radius
    tilt = math.radians(SLANTED_TILT)
    origins, directions = [], []
    for share in SLANTED_HEIGHTS:
        for az in np.radians(np.arange(8) * 45.0):
            radial = np.array([math.cos(az), math.sin(az), 0.0])
            for sign in (-1.0, 1.0):
                origins.append(radial * radius + [0.0, 0.0, share * length])
                directions.append(math.cos(tilt) * radial + [0.0, 0.0, sign * math.sin(tilt)])
    return [RayGroup("tool", np.array(origins), np.array(directions))]


def arm_layout(spec: RobotSpec) -> list[RayGroup]:
    """Rays beside the paper's 129, an option of the observation (``ObservationConfig.arm_rays``):
    rings round the upper arm and the forearm, which no paper ray watches and which hit most
    of what the tool does not in broad worlds (docs/training.md, "What the arm hits"). Each
    of ``ARM_MOUNTS`` is a mount whose z axis runs along its link for ``SensorMount.length``;
    ``ARM_STATIONS`` rings of ``ARM_AZIMUTHS`` radial rays, 45 deg apart, start on that axis,
    inside the link, so a ray's reading is the clearance from the link's axis. Order: mount,
    then station from the mount's origin, then azimuth."""
    missing = [name for name in ARM_MOUNTS if spec.mounts.get(name) is None or not spec.mounts[name].length]
    if missing:
        raise ValueError(f"robot '{spec.name}' has no mounts {missing} with a length along their link; rays along "
                         f"the arm need RobotSpec.mounts {list(ARM_MOUNTS)} (see robots/ur5.py)")
    az = np.radians(np.arange(ARM_AZIMUTHS) * 360.0 / ARM_AZIMUTHS)
    radial = np.stack((np.cos(az), np.sin(az), np.zeros(ARM_AZIMUTHS)), axis=1)
    groups = []
    for name in ARM_MOUNTS:
        heights = (np.arange(ARM_STATIONS) + 0.5) * spec.mounts[name].length / ARM_STATIONS
        origins = np.zeros((ARM_STATIONS * ARM_AZIMUTHS, 3))
        origins[:, 2] = np.repeat(heights, ARM_AZIMUTHS)
        groups.append(RayGroup(name, origins, np.tile(radial, (ARM_STATIONS, 1))))
    return groups


EXTRA_RAYS = {"tip_back": ("tip-back", N_TIP_BACK, tip_back_layout), "slanted": ("slanted", N_SLANTED, slanted_layout),
              "arm_rays": ("arm-rays", N_ARM, arm_layout)}
"""The ray sets an observation may read after the paper's 129, in that order, by their
``ObservationConfig`` field: name, count, layout."""


def extra_sets(fields: Iterable[str]) -> list[tuple[str, int, Callable[[RobotSpec], list[RayGroup]]]]:
    """The ``EXTRA_RAYS`` entries of these fields (``ObservationConfig.ray_sets``), in observation order."""
    fields = set(fields)
    unknown = fields - set(EXTRA_RAYS)
    if unknown:
        raise ValueError(f"unknown ray sets {sorted(unknown)}; valid: {', '.join(EXTRA_RAYS)}")
    return [entry for field, entry in EXTRA_RAYS.items() if field in fields]


def extra_layout(spec: RobotSpec, fields: Iterable[str]) -> list[RayGroup]:
    """The rays an observation reads after the paper's 129, set by set in ``EXTRA_RAYS`` order."""
    return [group for _, _, layout in extra_sets(fields) for group in layout(spec)]


def mount_offset(mount: SensorMount) -> np.ndarray:
    return pose_matrix(mount.xyz, rpy_to_matrix(mount.rpy))


def layout_rows(spec: RobotSpec, extra: Iterable[str] = ()) -> list[dict]:
    """Every ray in observation order, as a user mounts or emulates it: its sensor, the mount's
    link and chain frame, its origin and unit direction in the mount frame, in that chain
    frame (``origin_chain``, ``direction_chain``) and, for a mount on the flange, in the flange
    frame (chain frame n, the tool's axis along +z; None elsewhere). ``extra``: then the rays
    of those ``EXTRA_RAYS`` sets (indices from 129, in that table's order), which a policy
    observing them reads too."""
    groups = [(group, sensor) for group, sensor in zip(ray_layout(spec), SENSOR_SLICES)]
    groups += [(group, name) for name, _, layout in extra_sets(extra) for group in layout(spec)]
    rows = []
    for group, sensor in groups:
        mount = spec.mounts[group.mount]
        offset = mount_offset(mount)
        flange = mount.frame == spec.n_joints
        for origin, direction in zip(group.origins, group.directions):
            origin_chain = (offset[:3, :3] @ origin + offset[:3, 3]).round(6).tolist()
            direction_chain = (offset[:3, :3] @ direction).round(6).tolist()
            rows.append({"index": len(rows), "sensor": sensor, "mount": group.mount, "link": mount.link,
                         "frame": mount.frame, "origin": origin.round(6).tolist(),
                         "direction": direction.round(6).tolist(), "origin_chain": origin_chain,
                         "direction_chain": direction_chain, "origin_flange": origin_chain if flange else None,
                         "direction_flange": direction_chain if flange else None})
    return rows


class RayModel:
    """Turns chain frames into world ray origins and end points for one robot."""

    def __init__(self, spec: RobotSpec, ray_range: float = RAY_RANGE, groups: list[RayGroup] | None = None) -> None:
        """``groups``: the rays (default: the paper's 129, ``ray_layout``)."""
        self.ray_range = ray_range
        groups = ray_layout(spec) if groups is None else groups
        self.n_rays = sum(len(g.origins) for g in groups)
        # one block per mount (rays of a mount move together), each (frame, offset, rows,
        # local origins (n, 3), local directions (3, n)); rows keep the observation order
        self._blocks = []
        start = 0
        rows_of: dict[str, list[int]] = {}
        for g in groups:
            rows_of.setdefault(g.mount, []).extend(range(start, start + len(g.origins)))
            start += len(g.origins)
        all_o = np.concatenate([g.origins for g in groups])
        all_d = np.concatenate([g.directions for g in groups])
        for mount, rows in rows_of.items():
            if rows != list(range(rows[0], rows[-1] + 1)):
                raise ValueError(f"rays of mount '{mount}' must be contiguous in the layout")
            m = spec.mounts[mount]
            block = slice(rows[0], rows[-1] + 1)
            self._blocks.append((m.frame, mount_offset(m), block, all_o[block], all_d[block].T.copy()))

    @classmethod
    def extra(cls, spec: RobotSpec, ray_range: float = RAY_RANGE, fields: Iterable[str] = ()) -> "RayModel | None":
        """The rays of the ``EXTRA_RAYS`` sets ``fields`` (``extra_layout``) in place of the
        paper's; None where there are none."""
        groups = extra_layout(spec, fields)
        return cls(spec, ray_range, groups) if groups else None

    def world_rays(self, frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World origins and unit directions, each (n_rays, 3), from the robot's chain frames."""
        origins = np.empty((self.n_rays, 3))
        directions = np.empty((self.n_rays, 3))
        for frame, offset, rows, lo, ld in self._blocks:
            pose = frames[frame] @ offset
            rot = pose[:3, :3]
            origins[rows] = lo @ rot.T + pose[:3, 3]
            directions[rows] = (rot @ ld).T
        return origins, directions


class RayCaster(Protocol):
    """Casts rays of length ``ray_range`` and returns hit fractions in [0, 1]."""

    def cast(self, origins: np.ndarray, directions: np.ndarray, ray_range: float) -> np.ndarray: ...


@dataclass
class PrimitiveSet:
    """Obstacles as arrays, grouped by shape, in the form the numpy caster consumes.

    Poses are world positions and rotation matrices; ``half_extents`` for boxes, ``radius``
    for spheres, ``radius`` and ``half_height`` (along local z) for cylinders.
    """

    box_pos: np.ndarray
    box_rot: np.ndarray
    box_half: np.ndarray
    sphere_pos: np.ndarray
    sphere_radius: np.ndarray
    cyl_pos: np.ndarray
    cyl_rot: np.ndarray
    cyl_radius: np.ndarray
    cyl_half_height: np.ndarray

    @staticmethod
    def empty() -> "PrimitiveSet":
        z3, z33, z = np.zeros((0, 3)), np.zeros((0, 3, 3)), np.zeros(0)
        return PrimitiveSet(z3, z33, z3, z3, z, z3, z33, z, z)


_BIG = 1e30


def _first_hit(t_near: np.ndarray, t_far: np.ndarray) -> np.ndarray:
    """Per (obstacle, ray): entry distance if the segment [0, inf) meets the span, else +inf.

    A ray whose origin lies inside an obstacle hits at distance 0.
    """
    hit = (t_near <= t_far) & (t_far >= 0.0)
    return np.where(hit, np.maximum(t_near, 0.0), np.inf)


class NumpyCaster:
    """Analytic ray casting against boxes, spheres and cylinders, all rays at once.

    Rays are brought into the obstacles' frames with one matrix product per shape class and
    handled as (3, obstacles, rays) component planes: numpy is slow at broadcasting and
    reducing over a trailing axis of length 3, which would otherwise dominate.
    """

    def __init__(self, primitives: PrimitiveSet) -> None:
        self.primitives = primitives
        # rotations are fixed (moving obstacles only translate): stack R_k^T row blocks so
        # that (stack @ v) lists component i of R_k^T v at row i * K + k
        self._box_rt = self._stack(primitives.box_rot)
        self._cyl_rt = self._stack(primitives.cyl_rot)

    @staticmethod
    def _stack(rot: np.ndarray) -> np.ndarray:
        return np.ascontiguousarray(rot.transpose(2, 0, 1).reshape(-1, 3))

    def cast(self, origins: np.ndarray, directions: np.ndarray, ray_range: float) -> np.ndarray:
        prim = self.primitives
        best = np.full(len(origins), np.inf)
        if len(prim.box_pos):
            best = np.minimum(best, self._boxes(origins, directions).min(axis=0))
        if len(prim.sphere_pos):
            best = np.minimum(best, self._spheres(origins, directions).min(axis=0))
        if len(prim.cyl_pos):
            best = np.minimum(best, self._cylinders(origins, directions).min(axis=0))
        return np.minimum(best / ray_range, 1.0)

    @staticmethod
    def _local(stack: np.ndarray, rot: np.ndarray, pos: np.ndarray, origins: np.ndarray, directions: np.ndarray):
        """Ray origins and directions in each obstacle's frame as (3, K, n) planes."""
        k = len(pos)
        centre = np.einsum("kji,kj->ik", rot, pos)[:, :, None]  # R_k^T p_k, (3, K, 1)
        o = (stack @ origins.T).reshape(3, k, -1) - centre
        d = (stack @ directions.T).reshape(3, k, -1)
        return o, d

    def _boxes(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        prim = self.primitives
        o, d = self._local(self._box_rt, prim.box_rot, prim.box_pos, origins, directions)
        half = prim.box_half.T[:, :, None]
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / d  # +-inf for rays parallel to a slab; fmin/fmax skip the 0 * inf NaNs
            t1 = (-half - o) * inv
            t2 = (half - o) * inv
        lo, hi = np.fmin(t1, t2), np.fmax(t1, t2)
        t_near = np.fmax(np.fmax(lo[0], lo[1]), lo[2])
        t_far = np.fmin(np.fmin(hi[0], hi[1]), hi[2])
        return _first_hit(t_near, t_far)

    def _spheres(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        prim = self.primitives
        centres = prim.sphere_pos
        # |o + t d - c|^2 = r^2 with |d| = 1: t^2 + 2 b t + c' = 0
        b = np.einsum("nj,nj->n", origins, directions)[None, :] - centres @ directions.T
        oc2 = (
            np.einsum("nj,nj->n", origins, origins)[None, :]
            - 2.0 * centres @ origins.T
            + np.einsum("kj,kj->k", centres, centres)[:, None]
        )
        c = oc2 - prim.sphere_radius[:, None] ** 2
        disc = b * b - c
        root = np.sqrt(np.maximum(disc, 0.0))
        t_near = np.where(disc >= 0.0, -b - root, _BIG)
        t_far = np.where(disc >= 0.0, -b + root, -_BIG)
        return _first_hit(t_near, t_far)

    def _cylinders(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        prim = self.primitives
        o, d = self._local(self._cyl_rt, prim.cyl_rot, prim.cyl_pos, origins, directions)
        r = prim.cyl_radius[:, None]
        h = prim.cyl_half_height[:, None]
        # infinite cylinder x^2 + y^2 <= r^2
        a = d[0] ** 2 + d[1] ** 2
        b = o[0] * d[0] + o[1] * d[1]
        c = o[0] ** 2 + o[1] ** 2 - r**2
        disc = b * b - a * c
        parallel = a < 1e-12
        root = np.sqrt(np.maximum(disc, 0.0))
        a_safe = np.where(parallel, 1.0, a)
        side_near = np.where(parallel, np.where(c <= 0.0, -_BIG, _BIG), (-b - root) / a_safe)
        side_far = np.where(parallel, np.where(c <= 0.0, _BIG, -_BIG), (-b + root) / a_safe)
        missing = ~parallel & (disc < 0.0)
        side_near = np.where(missing, _BIG, side_near)
        side_far = np.where(missing, -_BIG, side_far)
        # slab |z| <= h
        with np.errstate(divide="ignore", invalid="ignore"):
            z1 = (-h - o[2]) / d[2]
            z2 = (h - o[2]) / d[2]
        t_near = np.fmax(side_near, np.fmin(z1, z2))
        t_far = np.fmin(side_far, np.fmax(z1, z2))
        return _first_hit(t_near, t_far)


class BulletCaster:
    """PyBullet's ``rayTestBatch``: the reference backend; sees every obstacle shape.

    The robot's collision group is left out of ``collisionFilterMask`` (see ``scene.py``),
    so rays pass through the arm and tool.
    """

    def __init__(self, client: int, collision_mask: int) -> None:
        self.client = client
        self.collision_mask = collision_mask

    def cast(self, origins: np.ndarray, directions: np.ndarray, ray_range: float) -> np.ndarray:
        import pybullet as p

        ends = origins + directions * ray_range
        hits = p.rayTestBatch(
            origins.tolist(),
            ends.tolist(),
            collisionFilterMask=self.collision_mask,
            physicsClientId=self.client,
        )
        return np.array([1.0 if h[0] < 0 else h[2] for h in hits])
