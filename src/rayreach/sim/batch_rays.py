"""The 129 rays of N worlds in one compiled call: their geometry from the DH frames and their
hit fractions against each world's boxes and spheres.

The arithmetic is ``RayModel.world_rays`` and ``NumpyCaster``'s (slab test for boxes, the
quadratic for spheres), per ray and obstacle in a loop that numba compiles. An exact
rejection test skips most obstacles: one whose bounding sphere misses the sphere round
all of a world's rays is not looked at. The rays of a world are laid out as coordinate
planes and tested without branches, so that the compiler vectorises the inner loops.
Neither changes a result.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from rayreach.sim.batch_obstacles import ObstacleBatch
from rayreach.sim.sensors import RayModel


@dataclass(frozen=True)
class RayArrays:
    """A robot's ray layout, per ray: its mount (DH frame and fixed offset) and its origin
    and unit direction in the mount frame."""

    mount_frame: np.ndarray
    mount_offset: np.ndarray
    ray_mount: np.ndarray
    origins: np.ndarray
    directions: np.ndarray

    @classmethod
    def of(cls, model: RayModel) -> "RayArrays":
        frames, offsets, mount, origins, directions = [], [], np.empty(model.n_rays, dtype=np.int64), [], []
        for m, (frame, offset, rows, lo, ld) in enumerate(model._blocks):
            frames.append(frame)
            offsets.append(offset)
            mount[rows] = m
            origins.append(lo)
            directions.append(ld.T)
        return cls(np.asarray(frames, dtype=np.int64), np.asarray(offsets, dtype=float), mount,
                   np.ascontiguousarray(np.concatenate(origins)),
                   np.ascontiguousarray(np.concatenate(directions)))


def place_rays(layout: RayArrays, frames: np.ndarray, worlds: np.ndarray, rays: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World origins and unit directions, each (k, 3), of ray ``rays[j]`` of world ``worlds[j]``
    with the arm at ``frames[worlds[j]]`` (``RayModel.world_rays`` for a few rays)."""
    mount = layout.ray_mount[rays]
    pose = frames[worlds, layout.mount_frame[mount]] @ layout.mount_offset[mount]
    rot = pose[:, :3, :3]
    origins = np.einsum("kij,kj->ki", rot, layout.origins[rays]) + pose[:, :3, 3]
    return origins, np.einsum("kij,kj->ki", rot, layout.directions[rays])


def cast_given(origins: np.ndarray, directions: np.ndarray, lengths: np.ndarray, obstacles: ObstacleBatch,
               which: np.ndarray, fractions: np.ndarray) -> None:
    """Hit fractions (``fractions[i]``, k each, 1: nothing within ``lengths[i]``) of rays
    placed by the caller, ``origins[i]`` and unit ``directions[i]`` (k, 3) of world ``i``, for
    every world ``i`` in ``which``; the rays of a world share its length (> 0)."""
    boxes, spheres = obstacles.boxes, obstacles.spheres
    _cast_given(origins, directions, lengths, boxes.pos, boxes.rot, boxes.size, boxes.count, spheres.pos,
                spheres.size, spheres.count, which, fractions)


def cast_worlds(layout: RayArrays, frames: np.ndarray, obstacles: ObstacleBatch, ray_range: float,
                which: np.ndarray, fractions: np.ndarray) -> None:
    """Hit fractions (``fractions[i]``, 129 each, 1: nothing within ``ray_range``) of the
    rays of every world ``i`` in ``which`` (indices), with the arm at ``frames[i]``."""
    boxes, spheres = obstacles.boxes, obstacles.spheres
    _cast(layout.mount_frame, layout.mount_offset, layout.ray_mount, layout.origins, layout.directions,
          frames, boxes.pos, boxes.rot, boxes.size, boxes.count, spheres.pos, spheres.size, spheres.count,
          float(ray_range), which, fractions)


@numba.njit(cache=True, inline="always")
def _fmin(a, b):  # pragma: no cover - compiled
    """``np.fmin``: the smaller, ignoring a NaN."""
    if a != a:
        return b
    if b != b:
        return a
    return a if a < b else b


@numba.njit(cache=True, inline="always")
def _fmax(a, b):  # pragma: no cover - compiled
    if a != a:
        return b
    if b != b:
        return a
    return a if a > b else b


@numba.njit(cache=True, error_model="numpy")
def _cast(mount_frame, mount_offset, ray_mount, local_o, local_d, frames, box_pos, box_rot, box_half, n_box,
          sphere_pos, sphere_size, n_sphere, ray_range, which, fractions):  # pragma: no cover - compiled
    n_rays = len(ray_mount)
    n_mounts = len(mount_frame)
    pose = np.empty((n_mounts, 3, 4))
    ox, oy, oz = np.empty(n_rays), np.empty(n_rays), np.empty(n_rays)
    dx, dy, dz = np.empty(n_rays), np.empty(n_rays), np.empty(n_rays)
    near, far = np.empty(n_rays), np.empty(n_rays)
    for w in which:
        fr = frames[w]
        for m in range(n_mounts):  # pose = frames[frame] @ offset
            f = fr[mount_frame[m]]
            off = mount_offset[m]
            for r in range(3):
                for c in range(4):
                    pose[m, r, c] = f[r, 0] * off[0, c] + f[r, 1] * off[1, c] + f[r, 2] * off[2, c] \
                        + f[r, 3] * off[3, c]
        for j in range(n_rays):
            p = pose[ray_mount[j]]
            lo0, lo1, lo2 = local_o[j, 0], local_o[j, 1], local_o[j, 2]
            ld0, ld1, ld2 = local_d[j, 0], local_d[j, 1], local_d[j, 2]
            ox[j] = lo0 * p[0, 0] + lo1 * p[0, 1] + lo2 * p[0, 2] + p[0, 3]
            oy[j] = lo0 * p[1, 0] + lo1 * p[1, 1] + lo2 * p[1, 2] + p[1, 3]
            oz[j] = lo0 * p[2, 0] + lo1 * p[2, 1] + lo2 * p[2, 2] + p[2, 3]
            dx[j] = p[0, 0] * ld0 + p[0, 1] * ld1 + p[0, 2] * ld2
            dy[j] = p[1, 0] * ld0 + p[1, 1] * ld1 + p[1, 2] * ld2
            dz[j] = p[2, 0] * ld0 + p[2, 1] * ld1 + p[2, 2] * ld2
        _first_hits(ox, oy, oz, dx, dy, dz, ray_range, box_pos[w], box_rot[w], box_half[w], n_box[w],
                    sphere_pos[w], sphere_size[w], n_sphere[w], near, far, fractions[w])


@numba.njit(cache=True, error_model="numpy")
def _cast_given(origins, directions, lengths, box_pos, box_rot, box_half, n_box, sphere_pos, sphere_size, n_sphere,
                which, fractions):  # pragma: no cover - compiled
    n_rays = origins.shape[1]
    ox, oy, oz = np.empty(n_rays), np.empty(n_rays), np.empty(n_rays)
    dx, dy, dz = np.empty(n_rays), np.empty(n_rays), np.empty(n_rays)
    near, far = np.empty(n_rays), np.empty(n_rays)
    for w in which:
        for j in range(n_rays):
            ox[j], oy[j], oz[j] = origins[w, j, 0], origins[w, j, 1], origins[w, j, 2]
            dx[j], dy[j], dz[j] = directions[w, j, 0], directions[w, j, 1], directions[w, j, 2]
        _first_hits(ox, oy, oz, dx, dy, dz, lengths[w], box_pos[w], box_rot[w], box_half[w], n_box[w],
                    sphere_pos[w], sphere_size[w], n_sphere[w], near, far, fractions[w])


@numba.njit(cache=True, error_model="numpy")
def _first_hits(ox, oy, oz, dx, dy, dz, ray_range, box_pos, box_rot, box_half, n_box, sphere_pos, sphere_size,
                n_sphere, near, far, out):  # pragma: no cover - compiled
    """One world's hit fractions of the rays (origins ``o*``, unit directions ``d*``, coordinate
    planes) into ``out``; ``near`` and ``far`` are scratch of the rays' length."""
    n_rays = len(ox)
    inf = np.inf
    c0, c1, c2 = ox.mean(), oy.mean(), oz.mean()
    spread = 0.0
    for j in range(n_rays):
        e0, e1, e2 = ox[j] - c0, oy[j] - c1, oz[j] - c2
        spread = max(spread, e0 * e0 + e1 * e1 + e2 * e2)
    reach = np.sqrt(spread) + ray_range
    for j in range(n_rays):
        out[j] = inf
    for k in range(n_box):
        pos, rot, half = box_pos[k], box_rot[k], box_half[k]
        bound = np.sqrt(half[0] * half[0] + half[1] * half[1] + half[2] * half[2])
        g0, g1, g2 = pos[0] - c0, pos[1] - c1, pos[2] - c2
        if g0 * g0 + g1 * g1 + g2 * g2 > (reach + bound) ** 2:
            continue
        near[:] = -inf  # lo and hi are never both NaN (that needs a flat box), so this is fmax's start
        far[:] = inf
        for a in range(3):  # the rays in the box's frame: R^T o - R^T p, as NumpyCaster has them
            ra0, ra1, ra2 = rot[0, a], rot[1, a], rot[2, a]
            centre = ra0 * pos[0] + ra1 * pos[1] + ra2 * pos[2]
            ha = half[a]
            for j in range(n_rays):
                oa = ra0 * ox[j] + ra1 * oy[j] + ra2 * oz[j] - centre
                inv = 1.0 / (ra0 * dx[j] + ra1 * dy[j] + ra2 * dz[j])
                t1 = (-ha - oa) * inv
                t2 = (ha - oa) * inv
                lo = _fmin(t1, t2)
                hi = _fmax(t1, t2)
                near[j] = _fmax(near[j], lo)
                far[j] = _fmin(far[j], hi)
        for j in range(n_rays):
            hit = near[j] <= far[j] and far[j] >= 0.0
            out[j] = min(out[j], max(near[j], 0.0) if hit else inf)
    for k in range(n_sphere):
        centre, radius = sphere_pos[k], sphere_size[k, 0]
        g0, g1, g2 = centre[0] - c0, centre[1] - c1, centre[2] - c2
        if g0 * g0 + g1 * g1 + g2 * g2 > (reach + radius) ** 2:
            continue
        cc = centre[0] * centre[0] + centre[1] * centre[1] + centre[2] * centre[2]
        r2 = radius * radius
        for j in range(n_rays):
            b = (ox[j] * dx[j] + oy[j] * dy[j] + oz[j] * dz[j]) \
                - (centre[0] * dx[j] + centre[1] * dy[j] + centre[2] * dz[j])
            oc2 = (ox[j] * ox[j] + oy[j] * oy[j] + oz[j] * oz[j]) \
                - 2.0 * (centre[0] * ox[j] + centre[1] * oy[j] + centre[2] * oz[j]) + cc
            disc = b * b - (oc2 - r2)
            root = np.sqrt(max(disc, 0.0))
            t_far = -b + root
            hit = disc >= 0.0 and t_far >= 0.0
            out[j] = min(out[j], max(-b - root, 0.0) if hit else inf)
    for j in range(n_rays):
        out[j] = min(out[j] / ray_range, 1.0)
