"""The observation's parts beyond the paper's, against what the environment did step by step."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from rayreach.env.observation import NEAR, WALL_RANGE, ObservationConfig
from rayreach.env.reach import OBS_SIZE, ReachEnv
from rayreach.sim.sensors import N_RAYS, N_TIP_BACK
from scenes import box_beside_the_forearm, plate_over_the_tip


def test_the_default_is_the_papers_observation():
    env = ReachEnv(robot="ur5")
    try:
        obs, _ = env.reset(seed=3)
        assert obs.shape == env.observation_space.shape == (OBS_SIZE,)
        assert ObservationConfig().is_paper and not ObservationConfig.planner().is_paper
    finally:
        env.close()


def test_planner_parts_hold_the_goal_the_walls_the_motion_and_past_scans():
    config = ObservationConfig.planner()
    env = ReachEnv(robot="ur5", observation=config, max_steps=200)
    rng = np.random.default_rng(0)
    try:
        obs, _ = env.reset(seed=5)
        assert obs.shape == env.observation_space.shape == (OBS_SIZE + 15 + 3 * (N_RAYS + 3) + N_TIP_BACK,)
        rays, ees, last = [env._ray_fractions.copy()], [env.ee_pos.copy()], env.ee_pos.copy()
        low, high = np.asarray(env.scenario.workspace_low), np.asarray(env.scenario.workspace_high)
        for t in range(1, 60):
            obs, _, terminated, truncated, _ = env.step(rng.uniform(-0.3, 0.3, 6).astype(np.float32))
            assert not (terminated or truncated), "the test wants 60 steps of one episode"
            rays.append(env._ray_fractions.copy())
            ees.append(env.ee_pos.copy())
            assert env.observation_space.contains(obs)
            np.testing.assert_array_equal(obs[:OBS_SIZE][13:], env._ray_fractions.astype(np.float32))
            k = OBS_SIZE
            offset = env.goals[0] - env.ee_pos
            np.testing.assert_allclose(obs[k:k + 3], offset / np.linalg.norm(offset), atol=1e-5)
            np.testing.assert_allclose(obs[k + 3:k + 6], np.clip(offset / NEAR, -1, 1), atol=1e-4)
            k += 6
            np.testing.assert_allclose(obs[k:k + 3], np.minimum(env.ee_pos - low, WALL_RANGE), atol=1e-6)
            np.testing.assert_allclose(obs[k + 3:k + 6], np.minimum(high - env.ee_pos, WALL_RANGE), atol=1e-6)
            k += 6
            np.testing.assert_allclose(obs[k:k + 3], (env.ee_pos - last) / env.spec_robot.ee_step, atol=1e-5)
            last = env.ee_pos.copy()
            k += 3
            for back in range(3):
                then = max(0, t - 8 * (back + 1))
                np.testing.assert_allclose(obs[k:k + N_RAYS], rays[then], atol=1e-6, err_msg=f"t={t} scan {back}")
                np.testing.assert_allclose(obs[k + N_RAYS:k + N_RAYS + 3], ees[then] - env.ee_pos, atol=1e-6)
                k += N_RAYS + 3
            np.testing.assert_array_equal(obs[k:], env._extra_fractions.astype(np.float32))
        assert np.ptp(np.array(rays), axis=0).max() > 0.05, "the scans should differ for the test to tell them apart"
        obs, _ = env.reset(seed=6)  # a new episode remembers nothing of the last
        k = OBS_SIZE + 15
        np.testing.assert_allclose(obs[k:k + N_RAYS], env._ray_fractions, atol=1e-6)
        np.testing.assert_allclose(obs[k + N_RAYS:k + N_RAYS + 3], 0.0, atol=1e-12)
    finally:
        env.close()


def test_set_observation_changes_the_space_from_the_next_reset():
    env = ReachEnv(robot="ur5")
    try:
        env.reset(seed=1)
        env.set_observation(ObservationConfig(workspace=True))
        with pytest.raises(RuntimeError, match="reset"):
            env.step(np.zeros(6, dtype=np.float32))
        obs, _ = env.reset(seed=1)
        assert obs.shape == env.observation_space.shape == (OBS_SIZE + 6,)
    finally:
        env.close()


@pytest.mark.parametrize("bad", [{"scans": -1}, {"scan_stride": 0}, {"sightings": -1}, {"sighting_window": 0}])
def test_bad_settings_are_refused(bad):
    with pytest.raises(ValueError, match=next(iter(bad))):
        ObservationConfig(**bad)


def test_tip_back_rays_see_a_plate_over_the_tip_as_pybullet_casts_them():
    """The tip-back part against PyBullet's ``rayTestBatch`` from the tool tip along the
    rings' directions, built here from the tool's pose: the plate a paper ray sees edge-on
    is seen from below."""
    import math

    import pybullet as p

    from rayreach.sim.scene import OBSTACLE_GROUP
    from rayreach.sim.sensors import TIP_BACK_POLAR

    config = ObservationConfig.planner()
    env = ReachEnv(scenario=plate_over_the_tip(back=0.05, centre_out=0.1, half=0.07), observation=config)
    try:
        obs, _ = env.reset(seed=0)
        assert obs.shape == env.observation_space.shape == (OBS_SIZE + config.extra_size(N_RAYS),)
        assert config.extra_size(N_RAYS) == 15 + 3 * 132 + 24
        seen = obs[-N_TIP_BACK:]
        local = np.array([[math.sin(math.radians(polar)) * math.cos(math.radians(az)),
                           math.sin(math.radians(polar)) * math.sin(math.radians(az)), math.cos(math.radians(polar))]
                          for polar in TIP_BACK_POLAR for az in range(0, 360, 30)])
        directions = local @ env.ee_rot.T
        ends = env.ee_pos + env.config.ray_range * directions
        hits = p.rayTestBatch([env.ee_pos.tolist()] * N_TIP_BACK, ends.tolist(), collisionFilterMask=OBSTACLE_GROUP,
                              physicsClientId=env.scene.client)
        expected = np.array([1.0 if h[0] < 0 else h[2] for h in hits])
        np.testing.assert_allclose(seen, expected, atol=1e-5)
        # azimuth 0 of each ring points at the plate, whose underside lies 4.8 cm up the tool:
        # 20 deg back from square meets it 13.2 cm out, 45 deg back 4.8 cm out
        underside = 0.05 - 0.002
        np.testing.assert_allclose(seen[[0, 12]], [underside / math.cos(math.radians(70)) / 0.4,
                                                   underside * math.sqrt(2) / 0.4], atol=1e-4)
        assert (seen < 1).sum() >= 4 and seen[6] == 1.0 and seen[18] == 1.0  # and nothing on the far side
    finally:
        env.close()


def test_slanted_rays_see_a_thin_plate_across_the_tool_that_the_wraparound_misses():
    """A 4 mm plate square to the tool's axis, beside it halfway up, lies between two rows of
    the wraparound's radial rays; the slanted part, against PyBullet's ``rayTestBatch`` along
    rays built here from the tool's pose, meets it from above and below."""
    import math

    import pybullet as p

    from rayreach.robots import get_robot
    from rayreach.sim.scene import OBSTACLE_GROUP
    from rayreach.sim.sensors import N_SLANTED, SENSOR_SLICES, SLANTED_HEIGHTS, SLANTED_TILT

    tool = get_robot("ur5").tool
    config = ObservationConfig.planner()
    slanted = replace(config, slanted=True)
    env = ReachEnv(scenario=plate_over_the_tip(back=tool.length / 2, centre_out=0.1, half=0.07), observation=slanted)
    try:
        obs, _ = env.reset(seed=0)
        assert obs.shape == env.observation_space.shape == (OBS_SIZE + config.extra_size(N_RAYS) + N_SLANTED,)
        rays = obs[OBS_SIZE - N_RAYS:OBS_SIZE]
        assert np.all(rays[SENSOR_SLICES["wraparound"]] == 1.0)  # edge-on between two rows
        seen = obs[-N_SLANTED:]
        tilt = math.radians(SLANTED_TILT)
        local_o, local_d = [], []
        for share in SLANTED_HEIGHTS:
            for az in range(0, 360, 45):
                radial = np.array([math.cos(math.radians(az)), math.sin(math.radians(az)), 0.0])
                for sign in (-1, 1):
                    local_o.append(radial * tool.radius + [0.0, 0.0, share * tool.length - tool.length])
                    local_d.append(math.cos(tilt) * radial + [0.0, 0.0, sign * math.sin(tilt)])
        origins = env.ee_pos + np.array(local_o) @ env.ee_rot.T  # from the tip back to the rays' heights
        ends = origins + env.config.ray_range * (np.array(local_d) @ env.ee_rot.T)
        hits = p.rayTestBatch(origins.tolist(), ends.tolist(), collisionFilterMask=OBSTACLE_GROUP,
                              physicsClientId=env.scene.client)
        np.testing.assert_allclose(seen, [1.0 if h[0] < 0 else h[2] for h in hits], atol=1e-5)
        # azimuth 0 points at the plate: from a quarter up towards the tip, from three quarters back
        gap = tool.length / 4 - 0.002
        np.testing.assert_allclose(seen[[1, 16]], gap * math.sqrt(2) / 0.4, atol=1e-4)
        assert seen[8] == seen[9] == 1.0  # azimuth 180 looks away from it
    finally:
        env.close()


def test_sightings_keep_the_nearest_point_of_each_window_where_it_was_seen():
    """Two windows of three steps, fed by hand: each holds the nearest point seen in it, as
    an offset from where the end effector is now over the ray range, until its slot starts
    a new window; a window that saw nothing reads as four zeros."""
    from rayreach.env.observation import Observer
    from rayreach.sim.sensors import RAY_RANGE

    config = ObservationConfig(sightings=2, sighting_window=3)
    observer = Observer(config, 1, N_RAYS, OBS_SIZE, 0.005)
    world, base, rays = np.array([0]), np.zeros((1, OBS_SIZE)), np.ones((1, N_RAYS))
    walls = (np.full((1, 3), -1.0), np.ones((1, 3)))
    nothing = (np.zeros((1, 3)), np.array([np.inf]))

    def seen(point, reach):
        return np.array([point], dtype=float), np.array([reach])

    ee = np.array([[0.1, 0.0, 0.0]])
    observer.reset(world, base, ee, rays, *walls, None, seen([0.3, 0.0, 0.0], 0.2))  # t = 0
    observer.step(world, base, ee, rays, *walls, None, seen([0.1, 0.1, 0.0], 0.1))   # t = 1, nearer
    observer.step(world, base, ee, rays, *walls, None, nothing)                      # t = 2
    part = observer.obs[0, OBS_SIZE:].reshape(2, 4)
    np.testing.assert_allclose(part[0], [0.0, 0.1 / RAY_RANGE, 0.0, 1.0])  # t = 0..2: the nearer one
    np.testing.assert_allclose(part[1], 0.0)  # before the episode: nothing
    moved = np.array([[0.1, 0.0, 0.1]])
    for _ in range(3):  # t = 3..5 see nothing; the end effector rises 10 cm
        observer.step(world, base, moved, rays, *walls, None, nothing)
    part = observer.obs[0, OBS_SIZE:].reshape(2, 4)
    np.testing.assert_allclose(part[0], 0.0)
    np.testing.assert_allclose(part[1], [0.0, 0.1 / RAY_RANGE, -0.1 / RAY_RANGE, 1.0])
    observer.step(world, base, moved, rays, *walls, None, seen([2.0, 0.0, 0.1], 0.05))  # t = 6: far, clipped
    part = observer.obs[0, OBS_SIZE:].reshape(2, 4)
    np.testing.assert_allclose(part[0], [1.0, 0.0, 0.0, 1.0])
    np.testing.assert_allclose(part[1], 0.0)  # the window of t = 0..2 has gone by
    observer.step(world, base, moved, rays, *walls, None, seen([0.1, 0.0, 0.0], 0.3))  # t = 7: farther along its ray
    np.testing.assert_allclose(observer.obs[0, OBS_SIZE:OBS_SIZE + 4], [1.0, 0.0, 0.0, 1.0])
    observer.reset(world, base, moved, rays, *walls, None, nothing)  # a new episode remembers nothing
    np.testing.assert_allclose(observer.obs[0, OBS_SIZE:], 0.0)
    with pytest.raises(ValueError, match="sighting"):
        observer.step(world, base, moved, rays, *walls)


def test_the_latest_sighting_is_the_nearest_hit_pybullet_finds_on_every_ray_the_policy_reads():
    """Over the plate over the tip, the paper's rays and the tip-back ones cast by PyBullet's
    ``rayTestBatch`` along the env's rays: the latest window's sighting is the hit point of
    the ray that hits nearest its origin, relative to the tool tip."""
    import pybullet as p

    from rayreach.sim.scene import OBSTACLE_GROUP
    from rayreach.sim.sensors import RAY_RANGE, RayModel

    config = replace(ObservationConfig.planner(), sightings=2)
    env = ReachEnv(scenario=plate_over_the_tip(back=0.05, centre_out=0.1, half=0.07), observation=config)
    try:
        obs, _ = env.reset(seed=0)
        assert obs.shape == env.observation_space.shape
        assert config.extra_size(N_RAYS) == ObservationConfig.planner().extra_size(N_RAYS) + 8
        origins, directions = env.rays.world_rays(env.frames)
        extra = RayModel.extra(env.spec_robot, RAY_RANGE, ["tip_back"]).world_rays(env.frames)
        origins, directions = np.concatenate((origins, extra[0])), np.concatenate((directions, extra[1]))
        hits = p.rayTestBatch(origins.tolist(), (origins + RAY_RANGE * directions).tolist(),
                              collisionFilterMask=OBSTACLE_GROUP, physicsClientId=env.scene.client)
        fractions = np.array([1.0 if h[0] < 0 else h[2] for h in hits])
        assert (fractions < 1).sum() >= 4
        nearest = [np.array(h[3]) for h, f in zip(hits, fractions) if f < fractions.min() + 1e-5]  # ties: any
        part = obs[-8:].reshape(2, 4)
        seen = env.ee_pos + RAY_RANGE * part[0, :3]
        assert min(np.linalg.norm(seen - point) for point in nearest) < 1e-5
        assert part[0, 3] == 1.0 and np.all(part[1] == 0.0)
    finally:
        env.close()


def test_the_arm_rays_read_a_box_beside_the_forearm_and_sight_it():
    """A box 0.12 m from the forearm's axis, square to its rays of azimuth 90 deg: of the 64
    arm rays (after the tip-back ones), the forearm's two middle rings read 0.12 m in that
    azimuth, PyBullet's ``rayTestBatch`` along them agrees, and the latest sighting is
    the point they hit (clipped, as every sighting, to the range's box round the tip)."""
    import pybullet as p

    from rayreach.sim.scene import OBSTACLE_GROUP
    from rayreach.sim.sensors import ARM_AZIMUTHS, ARM_STATIONS, N_ARM, RAY_RANGE

    config = replace(ObservationConfig.planner(), arm_rays=True, sightings=1)
    env = ReachEnv(scenario=box_beside_the_forearm(0.12), observation=config)
    try:
        obs, _ = env.reset(seed=0)
        start = OBS_SIZE + replace(config, arm_rays=False, sightings=0).extra_size(N_RAYS)
        arm = obs[start:start + N_ARM].reshape(2, ARM_STATIONS, ARM_AZIMUTHS)
        expected = np.ones_like(arm)
        expected[1, 1:3, 2] = 0.12 / RAY_RANGE
        np.testing.assert_allclose(arm, expected, atol=1e-6)
        origins, directions = env._extra_rays
        origins, directions = origins[-N_ARM:], directions[-N_ARM:]
        hits = p.rayTestBatch(origins.tolist(), (origins + RAY_RANGE * directions).tolist(),
                              collisionFilterMask=OBSTACLE_GROUP, physicsClientId=env.scene.client)
        np.testing.assert_allclose([1.0 if h[0] < 0 else h[2] for h in hits], arm.ravel(), atol=1e-6)
        ray = ARM_STATIONS * ARM_AZIMUTHS + ARM_AZIMUTHS + 2
        assert obs[-1] == 1.0
        # where it was seen relative to the tip, over the range and clipped (the forearm is farther)
        sighted = [np.clip((np.array(hits[r][3]) - env.ee_pos) / RAY_RANGE, -1, 1) for r in (ray, ray + ARM_AZIMUTHS)]
        assert min(np.abs(obs[-4:-1] - point).max() for point in sighted) < 1e-6
    finally:
        env.close()
