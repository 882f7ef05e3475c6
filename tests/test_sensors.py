"""Virtual laser sensors: the paper's ray layout, and the numpy caster against PyBullet's
``rayTestBatch`` (the reference) and against hand-computed distances.

About the reference: PyBullet's ray test against convex shapes is Bullet's approximate
sub-simplex convex cast. Head-on it is exact (errors ~1e-12 m), but at oblique incidence its
hit points lie up to 1.0 mm off the true surface (measured: up to 0.99 mm before it, up to
0.22 mm behind it), which for grazing rays changes the hit fraction by up to ~0.9 (a ray
that misses a sphere by 0.2 mm is reported as a hit). So the random-scene comparison checks
that every Bullet fraction lies between the numpy fractions of the same obstacles grown and
shrunk by ``BULLET_SURFACE_TOL``: both backends see the same geometry up to Bullet's
tolerance. Head-on cases are compared at 1e-6.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pybullet as p
import pytest
from geometry import signed_distance

from rayreach.scenarios.schema import ObstacleSpec
from rayreach.sim.scene import OBSTACLE_GROUP
from rayreach.sim.sensors import (
    N_RAYS,
    RAY_RANGE,
    SENSOR_SLICES,
    NumpyCaster,
    PrimitiveSet,
    RayModel,
    ray_layout,
)
from rayreach.sim.transforms import matrix_to_rpy, quaternion_to_matrix, rpy_to_matrix

BULLET_SURFACE_TOL = 1.05e-3
"""Bullet's ray hit points lie within this distance (m) of the analytic surface."""


# ---------------------------------------------------------------------- layout
def _polar_deg(d: np.ndarray, axis_sign: float = 1.0) -> np.ndarray:
    return np.degrees(np.arccos(np.clip(axis_sign * d[:, 2], -1, 1)))


def _azimuth_deg(d: np.ndarray) -> np.ndarray:
    return np.degrees(np.arctan2(d[:, 1], d[:, 0])) % 360.0


def test_slices_cover_the_129_rays_in_order():
    assert N_RAYS == 129
    assert list(SENSOR_SLICES) == ["wrist", "wraparound", "tip"]
    assert SENSOR_SLICES["wrist"] == slice(0, 24)
    assert SENSOR_SLICES["wraparound"] == slice(24, 104)
    assert SENSOR_SLICES["tip"] == slice(104, 129)


def test_layout_counts_and_unit_directions(rig):
    groups = ray_layout(rig.spec)
    assert [len(g.directions) for g in groups] == [24, 80, 25]
    assert [len(g.origins) for g in groups] == [24, 80, 25]
    for g, (name, sl) in zip(groups, SENSOR_SLICES.items()):
        assert sl.stop - sl.start == len(g.directions), name
        np.testing.assert_allclose(np.linalg.norm(g.directions, axis=1), 1.0, atol=1e-12)
    assert RayModel(rig.spec).n_rays == 129


def test_wrist_sensor_two_cones_at_40_degrees(rig):
    wrist = ray_layout(rig.spec)[0]
    d = wrist.directions
    np.testing.assert_allclose(wrist.origins, 0.0)
    # first cone opens along +z, the second along -z, both at a polar angle of 40 deg
    np.testing.assert_allclose(_polar_deg(d[:12]), 40.0, atol=1e-9)
    np.testing.assert_allclose(_polar_deg(d[12:], axis_sign=-1.0), 40.0, atol=1e-9)
    for cone in (d[:12], d[12:]):
        np.testing.assert_allclose(_azimuth_deg(cone), np.arange(12) * 30.0, atol=1e-9)
    # the mount sits on the tool axis behind the flange
    mount = rig.spec.mounts["wrist"]
    assert mount.frame == 6 and mount.xyz[0] == mount.xyz[1] == 0.0 and mount.xyz[2] < 0.0


def test_wraparound_sensor_8_columns_of_10(rig):
    wrap = ray_layout(rig.spec)[1]
    d, o = wrap.directions, wrap.origins
    length, radius = rig.spec.tool.length, rig.spec.tool.radius
    np.testing.assert_allclose(d[:, 2], 0.0, atol=1e-12)  # perpendicular to the tool
    heights = (np.arange(10) + 0.5) * length / 10
    for col in range(8):
        block = slice(10 * col, 10 * col + 10)
        np.testing.assert_allclose(_azimuth_deg(d[block]), 45.0 * col, atol=1e-9)
        # origins on the tool's surface, radially outwards, evenly along it from flange to tip
        np.testing.assert_allclose(np.hypot(o[block, 0], o[block, 1]), radius, atol=1e-12)
        np.testing.assert_allclose(o[block, :2], radius * d[block, :2], atol=1e-12)
        np.testing.assert_allclose(o[block, 2], heights, atol=1e-12)
    assert np.all(np.diff(heights) > 0) and 0 < heights[0] and heights[-1] < length


def test_tip_sensor_axis_and_two_rings(rig):
    tip = ray_layout(rig.spec)[2]
    d, o = tip.directions, tip.origins
    np.testing.assert_allclose(o, np.tile([0, 0, rig.spec.tool.length], (25, 1)), atol=1e-12)
    np.testing.assert_allclose(d[0], [0, 0, 1], atol=1e-12)
    np.testing.assert_allclose(_polar_deg(d[1:13]), 20.0, atol=1e-9)
    np.testing.assert_allclose(_polar_deg(d[13:25]), 40.0, atol=1e-9)
    for ring in (d[1:13], d[13:25]):
        np.testing.assert_allclose(_azimuth_deg(ring), np.arange(12) * 30.0, atol=1e-9)


def test_world_rays_follow_pybullet_link_frames(rig):
    """Ray origins and directions, placed from DH frames, equal the layout placed at PyBullet's
    own flange (tool0) and tool link poses."""
    rng = np.random.default_rng(3)
    wrist, wrap, tip = ray_layout(rig.spec)
    mount_z = rig.spec.mounts["wrist"].xyz[2]
    for _ in range(20):
        q = rig.random_q(rng)
        rig.scene.set_joints(q)
        origins, dirs = rig.rays.world_rays(rig.kin.frames(q))
        assert origins.shape == dirs.shape == (129, 3)
        np.testing.assert_allclose(np.linalg.norm(dirs, axis=1), 1.0, atol=1e-12)
        fpos, fquat = rig.scene.link_pose("tool0")
        frot = quaternion_to_matrix(fquat / np.linalg.norm(fquat))
        tpos, tquat = rig.scene.link_pose("rayreach_tool")
        trot = quaternion_to_matrix(tquat / np.linalg.norm(tquat))
        np.testing.assert_allclose(origins[:24], np.tile(fpos + mount_z * frot[:, 2], (24, 1)), atol=2e-6)
        np.testing.assert_allclose(dirs[:24], wrist.directions @ frot.T, atol=2e-6)
        np.testing.assert_allclose(origins[24:104], wrap.origins @ trot.T + tpos, atol=2e-6)
        np.testing.assert_allclose(dirs[24:104], wrap.directions @ trot.T, atol=2e-6)
        np.testing.assert_allclose(origins[104:], tip.origins @ trot.T + tpos, atol=2e-6)
        np.testing.assert_allclose(dirs[104:], tip.directions @ trot.T, atol=2e-6)
        tcp, _ = rig.scene.tcp_pose()
        np.testing.assert_allclose(origins[104], tcp, atol=2e-6)


# ---------------------------------------------------------------------- geometry helpers
def grown(obs: ObstacleSpec, delta: float) -> ObstacleSpec:
    """The obstacle with every size changed by ``delta`` (m; negative shrinks)."""
    if obs.shape == "box":
        return ObstacleSpec(
            "box", obs.position, obs.rpy, half_extents=tuple(h + delta for h in obs.half_extents)
        )
    if obs.shape == "sphere":
        return ObstacleSpec("sphere", obs.position, radius=obs.radius + delta)
    return ObstacleSpec(
        "cylinder", obs.position, obs.rpy, radius=obs.radius + delta, height=obs.height + 2 * delta
    )


def primitive_set(obstacles: list[ObstacleSpec]) -> PrimitiveSet:
    """Built here, independently of Scene, from the obstacle specs."""
    boxes = [o for o in obstacles if o.shape == "box"]
    spheres = [o for o in obstacles if o.shape == "sphere"]
    cyls = [o for o in obstacles if o.shape == "cylinder"]

    def pos(items):
        return np.array([o.position for o in items], dtype=float).reshape(-1, 3)

    def rot(items):
        return np.array([rpy_to_matrix(o.rpy) for o in items]).reshape(-1, 3, 3)

    return PrimitiveSet(
        box_pos=pos(boxes),
        box_rot=rot(boxes),
        box_half=np.array([o.half_extents for o in boxes]).reshape(-1, 3),
        sphere_pos=pos(spheres),
        sphere_radius=np.array([o.radius for o in spheres], dtype=float),
        cyl_pos=pos(cyls),
        cyl_rot=rot(cyls),
        cyl_radius=np.array([o.radius for o in cyls], dtype=float),
        cyl_half_height=np.array([o.height / 2 for o in cyls], dtype=float),
    )


def random_obstacle(rng: np.random.Generator, near: np.ndarray) -> ObstacleSpec:
    """A box, sphere or cylinder with sizes in [0.02, 0.15] m, randomly turned, centred within
    0.3 m of ``near``."""
    while True:
        offset = rng.uniform(-0.3, 0.3, 3)
        if np.linalg.norm(offset) <= 0.3:
            break
    centre = tuple(float(v) for v in near + offset)
    rpy = tuple(float(v) for v in rng.uniform(-math.pi, math.pi, 3))
    shape = str(rng.choice(["box", "sphere", "cylinder"]))
    if shape == "box":
        return ObstacleSpec(
            "box", centre, rpy, half_extents=tuple(float(v) for v in rng.uniform(0.02, 0.15, 3))
        )
    if shape == "sphere":
        return ObstacleSpec("sphere", centre, radius=float(rng.uniform(0.02, 0.15)))
    return ObstacleSpec(
        "cylinder",
        centre,
        rpy,
        radius=float(rng.uniform(0.02, 0.15)),
        height=float(2 * rng.uniform(0.02, 0.15)),
    )


def random_scenes(rigs, n_scenes: int, seed: int):
    """Yields (rig, obstacles, origins, directions): random arm pose, 1-6 obstacles near the
    tool tip, none containing (or within 5 mm of) a ray origin."""
    rng = np.random.default_rng(seed)
    names = ("ur5", "kr16")
    for k in range(n_scenes):
        rig = rigs[names[k % 2]]
        q = rig.random_q(rng)
        frames = rig.kin.frames(q)
        origins, dirs = rig.rays.world_rays(frames)
        tip = rig.kin.ee_from_frames(frames)[:3, 3]
        obstacles: list[ObstacleSpec] = []
        n = int(rng.integers(1, 7))
        while len(obstacles) < n:
            obs = random_obstacle(rng, tip)
            if signed_distance(obs, origins).min() > 5e-3:
                obstacles.append(obs)
        rig.scene.set_joints(q)
        yield rig, obstacles, origins, dirs


# ---------------------------------------------------------------------- numpy vs bullet
def test_numpy_caster_agrees_with_bullet_in_random_scenes(rigs):
    n_scenes, n_hits, n_exact = 240, 0, 0
    try:
        for rig, obstacles, origins, dirs in random_scenes(rigs, n_scenes, seed=77):
            rig.scene.set_obstacles(obstacles)
            f_np = rig.scene.caster("numpy").cast(origins, dirs, RAY_RANGE)
            f_bt = rig.scene.caster("bullet").cast(origins, dirs, RAY_RANGE)
            # the scene's numpy caster equals one built here from the specs
            np.testing.assert_array_equal(
                f_np, NumpyCaster(primitive_set(obstacles)).cast(origins, dirs, RAY_RANGE)
            )
            f_big = NumpyCaster(primitive_set([grown(o, BULLET_SURFACE_TOL) for o in obstacles])).cast(
                origins, dirs, RAY_RANGE
            )
            f_small = NumpyCaster(primitive_set([grown(o, -BULLET_SURFACE_TOL) for o in obstacles])).cast(
                origins, dirs, RAY_RANGE
            )
            assert np.all((f_np >= 0) & (f_np <= 1)) and np.all((f_bt >= 0) & (f_bt <= 1))
            assert np.all(f_big <= f_np + 1e-12) and np.all(f_np <= f_small + 1e-12)
            bad = np.nonzero((f_bt < f_big - 1e-9) | (f_bt > f_small + 1e-9))[0]
            assert len(bad) == 0, (
                f"{rig.name}: rays {bad.tolist()} numpy {f_np[bad]} bullet {f_bt[bad]} "
                f"bracket {f_big[bad]}..{f_small[bad]} obstacles {obstacles}"
            )
            n_hits += int(np.sum(f_np < 1))
            n_exact += int(np.sum((f_np < 1) & (np.abs(f_np - f_bt) <= 1e-4)))
    finally:
        for rig in rigs.values():
            rig.scene.set_obstacles([])
    assert n_hits > 5000  # the scenes really exercise the casters
    assert n_exact > 0.5 * n_hits  # most hits agree to 1e-4 even with Bullet's tolerance


def test_bullet_hit_points_lie_on_the_obstacle_surface(rigs):
    """Validates the reference itself and that Scene builds the obstacles as specified (sizes,
    cylinder height, orientation): Bullet's hit points are within its tolerance of the surface
    computed here from the spec."""
    worst = 0.0
    try:
        for rig, obstacles, origins, dirs in random_scenes(rigs, 60, seed=78):
            rig.scene.set_obstacles(obstacles)
            hits = p.rayTestBatch(
                origins.tolist(),
                (origins + RAY_RANGE * dirs).tolist(),
                collisionFilterMask=OBSTACLE_GROUP,
                physicsClientId=rig.scene.client,
            )
            points = np.array([h[3] for h in hits if h[0] >= 0]).reshape(-1, 3)
            if len(points):
                sdf = np.min([signed_distance(o, points) for o in obstacles], axis=0)
                worst = max(worst, float(np.abs(sdf).max()))
    finally:
        for rig in rigs.values():
            rig.scene.set_obstacles([])
    assert worst <= BULLET_SURFACE_TOL


# ---------------------------------------------------------------------- analytic cases
BACKENDS = ("numpy", "bullet")


def _cast(scene, backend, origin, direction):
    d = np.asarray(direction, dtype=float)
    return scene.caster(backend).cast(
        np.array([origin], float), np.array([d / np.linalg.norm(d)]), RAY_RANGE
    )[0]


@pytest.fixture
def ur5_scene(rigs):
    scene = rigs["ur5"].scene
    scene.set_obstacles([])
    yield scene
    scene.set_obstacles([])


CENTRE = np.array([0.3, 0.6, 1.2])  # away from the robot; it is invisible to rays anyway


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("distance", [0.0005, 0.05, 0.123, 0.3, 0.399])
def test_box_face_at_known_distance(ur5_scene, backend, distance):
    half = (0.1, 0.08, 0.05)
    ur5_scene.set_obstacles([ObstacleSpec("box", tuple(CENTRE), half_extents=half)])
    for axis, sign in [(2, 1), (0, -1), (1, 1)]:
        origin = CENTRE.copy()
        origin[axis] += sign * (half[axis] + distance)
        direction = np.zeros(3)
        direction[axis] = -sign
        # Bullet's convex cast reports 0 for an origin within its 1 mm tolerance of the surface
        tol = BULLET_SURFACE_TOL / RAY_RANGE if backend == "bullet" and distance < 2e-3 else 1e-9
        assert _cast(ur5_scene, backend, origin, direction) == pytest.approx(distance / RAY_RANGE, abs=tol)


@pytest.mark.parametrize("backend", BACKENDS)
def test_turned_box_edge(ur5_scene, backend):
    """A cube turned 45 deg about z shows a vertical edge at half * sqrt(2) from its centre."""
    half = 0.05
    ur5_scene.set_obstacles(
        [ObstacleSpec("box", tuple(CENTRE), (0.0, 0.0, math.pi / 4), half_extents=(half,) * 3)]
    )
    origin = CENTRE + [0.3, 0.0, 0.01]
    expected = (0.3 - half * math.sqrt(2)) / RAY_RANGE
    # Bullet rounds box edges by its collision margin (measured: 0.41 mm late, a 1 mm margin)
    tol = 1e-9 if backend == "numpy" else BULLET_SURFACE_TOL / RAY_RANGE
    assert _cast(ur5_scene, backend, origin, [-1, 0, 0]) == pytest.approx(expected, abs=tol)
    # unturned, the face is at `half`
    ur5_scene.set_obstacles([ObstacleSpec("box", tuple(CENTRE), half_extents=(half,) * 3)])
    assert _cast(ur5_scene, backend, origin, [-1, 0, 0]) == pytest.approx((0.3 - half) / RAY_RANGE, abs=1e-6)


@pytest.mark.parametrize("backend", BACKENDS)
def test_sphere_at_known_distance(ur5_scene, backend):
    r = 0.07
    ur5_scene.set_obstacles([ObstacleSpec("sphere", tuple(CENTRE), radius=r)])
    # head on
    assert _cast(ur5_scene, backend, CENTRE + [0, 0, 0.25], [0, 0, -1]) == pytest.approx(
        (0.25 - r) / RAY_RANGE, abs=1e-6
    )
    # off-centre by b: the ray enters at L - sqrt(r^2 - b^2) (Bullet only to its 1 mm tolerance)
    b, length = 0.04, 0.2
    expected = (length - math.sqrt(r * r - b * b)) / RAY_RANGE
    got = _cast(ur5_scene, backend, CENTRE + [length, b, 0], [-1, 0, 0])
    tol = 1e-9 if backend == "numpy" else BULLET_SURFACE_TOL * 2 / RAY_RANGE
    assert got == pytest.approx(expected, abs=tol)
    # passing beside it: nothing
    assert _cast(ur5_scene, backend, CENTRE + [0.2, r + 0.005, 0], [-1, 0, 0]) == 1.0


@pytest.mark.parametrize("backend", BACKENDS)
def test_cylinder_side_and_cap(ur5_scene, backend):
    r, h = 0.04, 0.2
    # axis along world x (pitch pi/2 turns local z onto x)
    ur5_scene.set_obstacles(
        [ObstacleSpec("cylinder", tuple(CENTRE), (0.0, math.pi / 2, 0.0), radius=r, height=h)]
    )
    assert _cast(ur5_scene, backend, CENTRE + [0.3, 0, 0], [-1, 0, 0]) == pytest.approx(
        (0.3 - h / 2) / RAY_RANGE, abs=1e-6
    )
    assert _cast(ur5_scene, backend, CENTRE + [0.05, 0, 0.3], [0, 0, -1]) == pytest.approx(
        (0.3 - r) / RAY_RANGE, abs=1e-6
    )
    assert _cast(ur5_scene, backend, CENTRE + [0.05, 0.3, 0], [0, -1, 0]) == pytest.approx(
        (0.3 - r) / RAY_RANGE, abs=1e-6
    )
    # beyond the cap along the side: misses
    assert _cast(ur5_scene, backend, CENTRE + [h / 2 + 0.01, 0, 0.3], [0, 0, -1]) == 1.0


@pytest.mark.parametrize("backend", BACKENDS)
def test_nothing_in_range_gives_one(ur5_scene, backend):
    ur5_scene.set_obstacles([ObstacleSpec("box", tuple(CENTRE), half_extents=(0.05, 0.05, 0.05))])
    assert _cast(ur5_scene, backend, CENTRE + [0, 0, 0.05 + RAY_RANGE + 0.01], [0, 0, -1]) == 1.0  # too far
    assert _cast(ur5_scene, backend, CENTRE + [0, 0, 0.1], [0, 0, 1]) == 1.0  # behind the ray
    assert _cast(ur5_scene, backend, CENTRE + [0, 0.2, 0], [1, 0, 0]) == 1.0  # beside it


def test_numpy_ray_starting_inside_an_obstacle_reports_zero(ur5_scene):
    ur5_scene.set_obstacles([ObstacleSpec("sphere", tuple(CENTRE), radius=0.05)])
    assert _cast(ur5_scene, "numpy", CENTRE + [0.01, 0, 0], [1, 0, 0]) == 0.0


def test_numpy_nearest_obstacle_wins(ur5_scene):
    ur5_scene.set_obstacles(
        [
            ObstacleSpec("box", tuple(CENTRE + [0.2, 0, 0]), half_extents=(0.01, 0.05, 0.05)),
            ObstacleSpec("sphere", tuple(CENTRE + [0.1, 0, 0]), radius=0.02),
            ObstacleSpec("cylinder", tuple(CENTRE + [0.3, 0, 0]), radius=0.02, height=0.1),
        ]
    )
    for backend in BACKENDS:
        assert _cast(ur5_scene, backend, CENTRE, [1, 0, 0]) == pytest.approx(0.08 / RAY_RANGE, abs=1e-6)


def test_rays_never_see_the_robot(rig):
    """Empty scene: every ray reads 1 with Bullet although many start inside or next to the
    arm's meshes and the tool cylinder (the robot's group is masked out)."""
    rng = np.random.default_rng(17)
    bullet = rig.scene.caster("bullet")
    for _ in range(30):
        q = rig.random_q(rng)
        rig.scene.set_joints(q)
        origins, dirs = rig.rays.world_rays(rig.kin.frames(q))
        np.testing.assert_array_equal(bullet.cast(origins, dirs, RAY_RANGE), np.ones(129))
        np.testing.assert_array_equal(rig.scene.caster("numpy").cast(origins, dirs, RAY_RANGE), np.ones(129))
    # the same rays do hit the robot when nothing is masked: the test above can fail
    hits = p.rayTestBatch(
        origins.tolist(), (origins + RAY_RANGE * dirs).tolist(), physicsClientId=rig.scene.client
    )
    assert any(h[0] == rig.scene.robot for h in hits)


def test_caster_selection(ur5_scene, tmp_path):
    assert isinstance(ur5_scene.caster("auto"), NumpyCaster)
    with pytest.raises(ValueError, match="auto, numpy, bullet"):
        ur5_scene.caster("optix")
    cube = tmp_path / "cube.obj"
    verts = [(x, y, z) for x in (-0.05, 0.05) for y in (-0.05, 0.05) for z in (-0.05, 0.05)]
    faces = [(1, 2, 4, 3), (5, 7, 8, 6), (1, 5, 6, 2), (3, 4, 8, 7), (1, 3, 7, 5), (2, 6, 8, 4)]
    cube.write_text(
        "".join(f"v {x} {y} {z}\n" for x, y, z in verts)
        + "".join(f"f {a} {b} {c} {d}\n" for a, b, c, d in faces)
    )
    ur5_scene.set_obstacles([ObstacleSpec("mesh", tuple(CENTRE), file=str(cube))])
    assert not isinstance(ur5_scene.caster("auto"), NumpyCaster)
    with pytest.raises(ValueError, match="meshes"):
        ur5_scene.caster("numpy")
    got = _cast(ur5_scene, "auto", CENTRE + [0, 0, 0.25], [0, 0, -1])
    assert got == pytest.approx(0.2 / RAY_RANGE, abs=0.01)  # a mesh's convex hull keeps a small margin


@pytest.mark.parametrize("robot", ["ur5", "kr16", "ur10"])
def test_the_printed_layout_is_the_one_the_rays_are_cast_from(robot, rigs, capsys, tmp_path):
    """``rayreach rays --json`` (docs/rays.md): each ray's origin and direction in the flange
    frame, carried by the flange's pose, are the ray ``RayModel`` casts; the picture is drawn."""
    from rayreach.cli import main

    assert main(["rays", "--robot", robot, "--json", "--plot", str(tmp_path / "rays.png")]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert [r["index"] for r in rows] == list(range(129))
    assert [r["sensor"] for r in rows] == ["wrist"] * 24 + ["wraparound"] * 80 + ["tip"] * 25
    assert (tmp_path / "rays.png").stat().st_size > 10_000
    rig = rigs[robot]
    frames = rig.kin.frames(rig.random_q(np.random.default_rng(8)))
    origins, directions = rig.rays.world_rays(frames)
    flange = frames[6]
    np.testing.assert_allclose(np.array([r["origin_flange"] for r in rows]) @ flange[:3, :3].T + flange[:3, 3],
                               origins, atol=2e-6)
    np.testing.assert_allclose(np.array([r["direction_flange"] for r in rows]) @ flange[:3, :3].T, directions,
                               atol=2e-6)


def test_layout_rows_with_tip_back_list_its_rays_after_the_129():
    """``rayreach rays --tip-back``: rays 129-152 start at the tool tip and look back
    towards the flange (negative z in the flange frame), 110 and 135 degrees off the axis."""
    from rayreach.robots import get_robot
    from rayreach.sim.sensors import N_TIP_BACK, layout_rows

    spec = get_robot("ur5")
    rows = layout_rows(spec, ["tip_back"])
    assert [r["index"] for r in rows] == list(range(N_RAYS + N_TIP_BACK))
    assert layout_rows(spec) == rows[:N_RAYS]
    back = rows[N_RAYS:]
    assert {r["sensor"] for r in back} == {"tip-back"}
    for r in back:
        np.testing.assert_allclose(r["origin_flange"], [0.0, 0.0, spec.tool.length], atol=1e-6)
    z = np.array([r["direction_flange"][2] for r in back])
    np.testing.assert_allclose(z, np.repeat(np.cos(np.radians([110.0, 135.0])), 12), atol=1e-6)


def test_layout_rows_list_the_slanted_rays_after_the_tip_back_ones():
    """``rayreach rays --tip-back --slanted``: the 32 slanted rays follow the 24 tip-back ones;
    each starts on the tool's surface at a quarter or three quarters of its length and leaves
    it 45 degrees off square, towards the flange and the tip in turn."""
    from rayreach.robots import get_robot
    from rayreach.sim.sensors import N_SLANTED, N_TIP_BACK, layout_rows

    spec = get_robot("kr16")
    rows = layout_rows(spec, ["tip_back", "slanted"])
    assert [r["index"] for r in rows] == list(range(N_RAYS + N_TIP_BACK + N_SLANTED))
    assert rows[:N_RAYS + N_TIP_BACK] == layout_rows(spec, ["tip_back"])
    alone = layout_rows(spec, ["slanted"])[N_RAYS:]
    assert [r["index"] for r in alone] == list(range(N_RAYS, N_RAYS + N_SLANTED))
    slanted = rows[N_RAYS + N_TIP_BACK:]
    assert {r["sensor"] for r in slanted} == {"slanted"}
    origins = np.array([r["origin"] for r in slanted])
    directions = np.array([r["direction"] for r in slanted])
    np.testing.assert_allclose(np.hypot(origins[:, 0], origins[:, 1]), spec.tool.radius, atol=1e-6)
    np.testing.assert_allclose(origins[:, 2], np.repeat([0.25, 0.75], 16) * spec.tool.length, atol=1e-6)
    np.testing.assert_allclose(np.linalg.norm(directions, axis=1), 1.0, atol=1e-6)
    np.testing.assert_allclose(directions[:, 2], np.tile([-1.0, 1.0], 16) * np.sqrt(0.5), atol=1e-6)
    # each leaves the surface outwards, along its origin's radial direction
    outward = origins[:, :2] / spec.tool.radius
    np.testing.assert_allclose(np.sum(outward * directions[:, :2], axis=1), np.sqrt(0.5), atol=1e-4)  # rounded rows


# ---------------------------------------------------------------------- rays along the arm
def _arm_rays(rig) -> RayModel:
    return RayModel.extra(rig.spec, RAY_RANGE, ["arm_rays"])


NEXT_LINK = {("kr16", "link_3"): ("link_4",)}
"""Links an arm mount's rings run on into."""


def test_arm_rays_ring_the_upper_arm_and_the_forearm_from_inside(rig):
    """Each ring's centre lies inside its mount's link as PyBullet holds it (the KR16's forearm
    rings run on into link_4, which turns about their axis), and each mount moves with its
    URDF link: its pose in PyBullet's link frame is the same in every configuration."""
    from rayreach.sim.sensors import ARM_AZIMUTHS, ARM_MOUNTS, ARM_STATIONS, N_ARM, mount_offset

    rng = np.random.default_rng(5)
    rays = _arm_rays(rig)
    assert rays.n_rays == N_ARM == len(ARM_MOUNTS) * ARM_STATIONS * ARM_AZIMUTHS
    probe = p.createCollisionShape(p.GEOM_SPHERE, radius=1e-4, physicsClientId=rig.scene.client)
    in_link = {name: [] for name in ARM_MOUNTS}
    for _ in range(5):
        q = rig.random_q(rng)
        rig.scene.set_joints(q)
        frames = rig.kin.frames(q)
        origins, directions = rays.world_rays(frames)
        centres = origins[::ARM_AZIMUTHS]
        for k, centre in enumerate(centres):
            mount = rig.spec.mounts[ARM_MOUNTS[k // ARM_STATIONS]]
            links = {mount.link, *NEXT_LINK.get((rig.name, mount.link), ())}
            depth = min(c[8] for link in links
                        for c in p.getClosestPoints(rig.scene.robot, -1, 0.05, linkIndexA=rig.scene.link_indices[link],
                                                    collisionShapeB=probe, collisionShapePositionB=centre.tolist(),
                                                    physicsClientId=rig.scene.client))
            assert depth < -0.01, (mount.link, k)  # over a centimetre inside
        for name in ARM_MOUNTS:
            mount = rig.spec.mounts[name]
            pose = frames[mount.frame] @ mount_offset(mount)
            pos, quat = rig.scene.link_pose(mount.link)
            rot = quaternion_to_matrix(quat / np.linalg.norm(quat))
            in_link[name].append(np.concatenate((rot.T @ (pose[:3, 3] - pos), (rot.T @ pose[:3, :3]).ravel())))
        # radial: each ray square to its ring's axis, the rings spaced along it
        axis = (centres[1] - centres[0]) / np.linalg.norm(centres[1] - centres[0])
        np.testing.assert_allclose(directions[:ARM_STATIONS * ARM_AZIMUTHS] @ axis, 0.0, atol=1e-9)
    for name, poses in in_link.items():
        np.testing.assert_allclose(poses, np.repeat(poses[:1], len(poses), axis=0), atol=1e-6, err_msg=name)


@pytest.mark.parametrize("backend", BACKENDS)
def test_arm_rays_see_a_box_beside_the_upper_arm_that_no_paper_ray_sees(rigs, backend):
    """A box 0.15 m from the upper arm's axis, square to one of its rays: that ray reads its
    distance, and none of the paper's 129 sees it."""
    from rayreach.sim.sensors import ARM_AZIMUTHS, ARM_STATIONS

    rig = rigs["ur5"]
    q = np.asarray(rig.spec.home)
    rig.scene.set_joints(q)
    frames = rig.kin.frames(q)
    origins, directions = _arm_rays(rig).world_rays(frames)
    ray = ARM_AZIMUTHS + 2  # the upper arm's second ring
    face = origins[ray] + 0.15 * directions[ray]
    centre = face + 0.05 * directions[ray]
    # a 0.1 m cube with one face through ``face``, square to the ray
    x = directions[ray]
    y = np.cross(x, [0.0, 0.0, 1.0]) if abs(x[2]) < 0.9 else np.cross(x, [1.0, 0.0, 0.0])
    y /= np.linalg.norm(y)
    rot = np.stack((x, y, np.cross(x, y)), axis=1)
    rpy = tuple(float(v) for v in matrix_to_rpy(rot))
    rig.scene.set_obstacles([ObstacleSpec("box", tuple(centre), rpy, half_extents=(0.05, 0.05, 0.05))])
    try:
        caster = rig.scene.caster(backend)
        seen = caster.cast(origins, directions, RAY_RANGE)
        assert seen[ray] == pytest.approx(0.15 / RAY_RANGE, abs=1e-3)
        assert seen[:ARM_STATIONS * ARM_AZIMUTHS].min() == seen[ray]
        paper = caster.cast(*rig.rays.world_rays(frames), RAY_RANGE)
        np.testing.assert_array_equal(paper, np.ones(N_RAYS))
    finally:
        rig.scene.set_obstacles([])


def test_layout_rows_list_the_arm_rays_in_their_mount_frames(capsys):
    """``rayreach rays --arm-rays``: the 64 rays follow the 129, each with its mount's link and
    chain frame and no place in the flange frame, which moves against them. The KR16's upper
    arm runs along -x of chain frame 2, 0.15 m beside the joint axes; its forearm along z of
    chain frame 3; the rings sit at the middles of the links' quarters."""
    from rayreach.cli import main
    from rayreach.robots import get_robot
    from rayreach.sim.sensors import N_ARM, layout_rows

    spec = get_robot("kr16")
    rows = layout_rows(spec, ["arm_rays"])
    arm = rows[N_RAYS:]
    assert len(arm) == N_ARM and {r["sensor"] for r in arm} == {"arm-rays"}
    assert [r["frame"] for r in arm] == [2] * 32 + [3] * 32
    assert all(r["origin_flange"] is None and r["direction_flange"] is None for r in arm)
    quarters = (np.arange(4) + 0.5) / 4
    upper = np.array([r["origin_chain"] for r in arm[:32:8]])
    np.testing.assert_allclose(upper, np.stack((-0.68 * quarters, np.zeros(4), np.full(4, -0.15)), axis=1), atol=1e-6)
    fore = np.array([r["origin_chain"] for r in arm[32::8]])
    np.testing.assert_allclose(fore, np.stack((np.zeros(4), np.zeros(4), 0.67 * quarters), axis=1), atol=1e-6)
    np.testing.assert_allclose([r["direction_chain"][2] for r in arm[32:]], 0.0, atol=1e-6)  # square to the forearm
    assert main(["rays", "--robot", "kr16", "--arm-rays"]) == 0
    printed = capsys.readouterr().out.splitlines()
    assert printed[-1].split()[:4] == [str(N_RAYS + N_ARM - 1), "arm-rays", "link_3", "3"]


def test_arm_rays_need_mounts_along_the_links():
    from dataclasses import replace

    from rayreach.robots import get_robot
    from rayreach.sim.sensors import arm_layout

    spec = get_robot("ur5")
    bare = replace(spec, mounts={k: v for k, v in spec.mounts.items() if k != "forearm"})
    with pytest.raises(ValueError, match=r"no mounts \['forearm'\].*upper_arm"):
        arm_layout(bare)
    with pytest.raises(ValueError, match="valid: tip_back, slanted, arm_rays"):
        RayModel.extra(spec, RAY_RANGE, ["elbow"])
