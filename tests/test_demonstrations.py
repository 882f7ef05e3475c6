"""Scripted demonstrations: the shelf expert enters every compartment of exp4..exp7, the slot
expert reaches both goals of exp2, and cloning an expert into a checkpoint keeps the run
resumable."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pybullet as p
import pytest

from rayreach.learning.demonstrations import (CoverExpert, ShelfExpert, SlotExpert, bottom_of, clonable_kinds,
                                              horizontal_gap, horizontal_reach, top_of)
from rayreach.env.decisions import HeldAction
from rayreach.env.reach import ReachEnv
from rayreach.robots import get_robot
from rayreach.scenarios.broad_world import broad_kinds
from rayreach.scenarios.random_world import RandomWorldConfig
from rayreach.learning.bundles import read_bundle_meta


def test_expert_levels_and_centres_the_tool_before_advancing():
    expert = ShelfExpert()
    obs = np.zeros(142, dtype=np.float32)
    obs[6:9] = (0.02, 0.4, -0.01)  # goal 2 cm right, 40 cm in, 1 cm below
    tilted = np.array([0.0, np.cos(np.pi / 6), -np.sin(np.pi / 6)])
    action = expert.action(obs, tilted)
    assert action[1] == 0.0  # no advance while tilted or off-centre
    assert action[0] == 1.0 and action[2] == pytest.approx(-0.01 / 0.005 * 0.5, abs=1.0)
    assert action[3] > 0.5 and abs(action[4]) < 1e-6  # pitches up about +x: z turns towards +y
    level = np.array([0.0, 1.0, 0.0])
    obs[6:9] = (0.001, 0.4, -0.001)
    action = expert.action(obs, level)
    assert action[1] == 1.0 and np.allclose(action[3:], 0.0)
    obs[6:9] = (0.02, 0.4, -0.01)
    closing = expert.action(obs, tilted, approach=0.002)  # may close in 2 mm on the face while turning
    assert closing[1] == pytest.approx(0.4) and closing[0] == 1.0


def _clearance(scene) -> float:
    """Least distance from the robot to any obstacle, by PyBullet's closest points."""
    points = [point[8] for body in scene._obstacle_ids
              for point in p.getClosestPoints(scene.robot, body, 0.05, physicsClientId=scene.client)]
    return min(points, default=np.inf)


def _follow(env, base: ReachEnv, expert, obs: np.ndarray) -> tuple[dict, float]:
    """Step ``env`` (``base`` inside it) by ``expert``'s labels from ``obs`` to the episode's
    end: its last info and the least clearance on the way, by PyBullet's closest points."""
    done, clearance, info = False, np.inf, {}
    while not done:
        obs, _, terminated, truncated, info = env.step(expert.label(obs, base))
        done = terminated or truncated
        clearance = min(clearance, _clearance(base.scene))
    return info, clearance


@pytest.mark.parametrize("name", ["exp4", "exp5", "exp6", "exp7"])
def test_expert_reaches_each_compartment_goal_without_touching_the_shelf(name):
    """Checked against PyBullet's own closest points at every step, not the env's flag."""
    env = ReachEnv(robot="kr16", scenario=name)
    expert = ShelfExpert()
    try:
        obs, info = env.reset(seed=0)
        done, clearance, advanced_tilted = False, np.inf, False
        while not done:
            action = expert.label(obs, env)
            near = env.ee_pos[1] > 0.1 - expert.standoff + 1e-3  # the shelf's open face is at y = 0.1
            if action[1] > 0 and near and env.ee_rot[1, 2] < np.cos(0.03):
                advanced_tilted = True
            obs, _, terminated, truncated, info = env.step(action)
            done = terminated or truncated
            clearance = min(clearance, _clearance(env.scene))
        assert info["is_success"] and not info["collision"]
        assert info["distance"] < 0.01
        assert clearance > 0.0
        assert not advanced_tilted  # by the face, it advances only levelled
        assert env.steps < 300
    finally:
        env.close()


def test_slot_expert_climbs_while_far_crosses_level_and_descends_only_above_the_goal():
    expert = SlotExpert()
    obs = np.zeros(142, dtype=np.float32)
    down = np.array([0.0, 0.0, -1.0])
    obs[6:9] = (-0.3, 0.0, -0.05)  # far: closes in while it climbs
    action = expert.action(obs, down, height=0.30, crossing=0.35, reach=0.17)
    assert action[0] == -1.0 and action[2] == 1.0 and np.allclose(action[3:], 0.0)
    obs[6:9] = (-0.15, 0.0, -0.05)  # within reach, below the crossing height: climbs only
    action = expert.action(obs, down, height=0.30, crossing=0.35, reach=0.17)
    assert action[0] == 0.0 and action[2] == 1.0
    obs[6:9] = (-0.15, 0.0, -0.1)  # at the crossing height: level, towards the goal
    action = expert.action(obs, down, height=0.35, crossing=0.35, reach=0.17)
    assert action[0] == -1.0 and action[2] == 0.0
    obs[6:9] = (0.001, 0.0, -0.1)  # above the goal: straight down
    action = expert.action(obs, down, height=0.35, crossing=0.35, reach=0.17)
    assert action[2] == -1.0 and abs(action[0]) < 0.5
    tilted = np.array([np.sin(0.1), 0.0, -np.cos(0.1)])
    assert expert.action(obs, tilted, height=0.35, crossing=0.35, reach=0.17)[4] > 0  # +y turns a +x lean down


def test_obstacle_top_and_reach_agree_with_pybullet_bounding_boxes():
    env = ReachEnv(robot="ur5", scenario="exp2")
    try:
        env.reset(seed=0)
        scene = env.scene
        goal = env.goals[0]
        for spec, body in zip(env.scenario.obstacles, scene._obstacle_ids):
            low, high = p.getAABB(body, physicsClientId=scene.client)
            assert top_of(spec) == pytest.approx(high[2], abs=1e-6)
            corners = np.array([[x, y] for x in (low[0], high[0]) for y in (low[1], high[1])])
            assert horizontal_reach(spec, goal) == pytest.approx(np.linalg.norm(corners - goal[:2], axis=1).max(), abs=1e-6)
    finally:
        env.close()


def test_slot_expert_reaches_both_goals_of_exp2_without_touching_a_plate():
    env = ReachEnv(robot="ur5", scenario="exp2")
    expert = SlotExpert()
    try:
        obs, info = env.reset(seed=0)
        info, clearance = _follow(env, env, expert, obs)
        assert info["is_success"] and not info["collision"] and info["goal_index"] == 1
        assert clearance > 0.0
        assert env.steps < 300
    finally:
        env.close()


def _cover_world() -> ReachEnv:
    return ReachEnv(robot="ur5", scenario="random", goal_tolerance=0.01,
                    random_world=RandomWorldConfig(n_obstacles=1, kinds=("goal_cover",)))


def test_a_moving_covers_gap_and_bottom_agree_with_pybullet_bounding_boxes():
    env = _cover_world()
    try:
        env.reset(seed=3)
        (cover,), (body,) = env.scenario.obstacles, env.scene._obstacle_ids
        goal = env.goals[0]
        for t in (0.0, 0.5, 1.5):
            env.scene.set_time(t)
            low, high = p.getAABB(body, physicsClientId=env.scene.client)
            outside = np.maximum(np.maximum(np.array(low[:2]) - goal[:2], goal[:2] - np.array(high[:2])), 0.0)
            assert horizontal_gap(cover, goal, t) == pytest.approx(np.linalg.norm(outside), abs=1e-6)
            assert bottom_of(cover) == pytest.approx(low[2], abs=1e-6)
        assert horizontal_gap(cover, goal, 0.0) == 0.0 and horizontal_gap(cover, goal, 1.5) > 0.0  # it moves off
    finally:
        env.close()


@pytest.mark.parametrize("period", [1, 4])
def test_cover_expert_waits_for_the_cover_where_diving_collides(period):
    """Goals under a plate that moves away: the cover expert reaches every one it accepts
    without touching the plate (PyBullet's closest points at every step), arriving after the
    plate has cleared the goal; the slot expert, the same way in without the wait, hits the
    plate in most of them. Actions held ``period`` control steps."""
    spec = get_robot("ur5")
    cover_expert = CoverExpert(ee_step=spec.ee_step * period, rot_step=spec.rot_step * period)
    experts = {"cover": cover_expert, "slot": SlotExpert(ee_step=spec.ee_step * period, rot_step=spec.rot_step * period)}
    base = _cover_world()
    env = HeldAction(base, period)
    outcomes: dict[str, list[tuple[bool, bool, float]]] = {"cover": [], "slot": []}
    try:
        for seed in range(12):
            for name, expert in experts.items():
                obs, info = env.reset(seed=seed)
                if not cover_expert.accepts(base):
                    break
                info, clearance = _follow(env, base, expert, obs)
                (cover,) = base.scenario.obstacles
                gap = horizontal_gap(cover, base.goals[0], base.time)
                outcomes[name].append((bool(info["is_success"]) and clearance > 0.0, bool(info["collision"]), gap))
    finally:
        env.close()
    assert len(outcomes["cover"]) >= 6
    assert all(clean and gap >= cover_expert.gap for clean, _, gap in outcomes["cover"])
    assert sum(collision for _, collision, _ in outcomes["slot"]) > len(outcomes["slot"]) / 2


def test_clone_keeps_the_step_count_and_adds_its_time(tmp_path):
    rayreach = [sys.executable, "-m", "rayreach.cli"]
    out = tmp_path / "run"
    trained = subprocess.run([*rayreach, "train", "--robot", "kr16", "--timesteps", "1024", "--envs", "2",
                              "--workers", "1", "--out", str(out), "--checkpoint-every", "1024"],
                             capture_output=True, text=True, timeout=240)
    assert trained.returncode == 0, trained.stderr[-2000:]
    before, _ = read_bundle_meta(out / "checkpoint.zip")
    cloned = subprocess.run([*rayreach, "clone", "--run", str(out), "--kind", "shelf", "--episodes", "2", "--rounds", "2",
                             "--anchor-episodes", "1", "--eval-episodes", "1"],
                            capture_output=True, text=True, timeout=240)
    assert cloned.returncode == 0, cloned.stderr[-2000:]
    after, norm = read_bundle_meta(out / "checkpoint.zip")
    assert after["kind"] == "checkpoint" and after["timesteps"] == before["timesteps"]
    assert after["state"]["wall_time"] > before["state"]["wall_time"]
    assert norm is not None and norm["obs_mean"].shape == tuple(before["obs_shape"])  # the run's observation
    report = json.loads((out / "clone-shelf.json").read_text())
    assert [r["followed"] for r in report["rounds"]] == ["expert", "cloned actor"]
    assert report["rounds"][0]["success_rate"] == 1.0  # the expert itself
    resumed = subprocess.run([*rayreach, "train", "--robot", "kr16", "--timesteps", "2048", "--envs", "2",
                              "--workers", "1", "--out", str(out), "--checkpoint-every", "1024", "--resume"],
                             capture_output=True, text=True, timeout=240)
    assert resumed.returncode == 0, resumed.stderr[-2000:]
    wrong = subprocess.run([*rayreach, "clone", "--run", str(out / "model.zip"), "--kind", "shelf"], capture_output=True,
                           text=True, timeout=60)
    assert wrong.returncode == 2 and "checkpoint" in wrong.stderr
    no_slots = subprocess.run([*rayreach, "clone", "--run", str(out), "--kind", "goal_slot"], capture_output=True,
                              text=True, timeout=60)
    assert no_slots.returncode == 2 and "does not train on 'goal_slot'" in no_slots.stderr and "shelf" in no_slots.stderr


def test_kinds_with_an_expert_follow_the_robot_and_the_suite():
    assert clonable_kinds("ur5", "random") == ("goal_cover", "goal_slot")
    assert clonable_kinds("kr16", "random") == ("shelf",)
    assert clonable_kinds("ur5", "broad") == clonable_kinds("kr16", "broad") == ("shelf", "goal_box")


def _broad_outcomes(expert_for, kind: str, worlds: int, robot: str = "ur5") -> list[bool]:
    """Whether ``expert_for(env)`` reaches the goal without a touch (PyBullet closest points)
    in each of the first ``worlds`` broad worlds of ``robot`` whose goal scene is ``kind`` and
    which it accepts, actions held 4 control steps."""
    spec = get_robot(robot)
    base = ReachEnv(robot=robot, scenario="broad", goal_tolerance=0.01, random_world=RandomWorldConfig(n_obstacles=1))
    env = HeldAction(base, 4)
    outcomes: list[bool] = []
    try:
        seed = 1_000_000
        while len(outcomes) < worlds:
            obs, _ = env.reset(seed=seed)
            seed += 1
            expert = expert_for(spec, base)
            if broad_kinds(base.scenario) != [kind] or not expert.accepts(base):
                continue
            info, clearance = _follow(env, base, expert, obs)
            outcomes.append(bool(info["is_success"]) and clearance > 0.0)
    finally:
        env.close()
    return outcomes


def test_shelf_expert_enters_broad_shelves_by_their_own_face():
    """A broad world's shelf faces the base from wherever it stands: the expert goes in along
    the shelf's own +y, turned by its yaw; held to the random worlds' +y it fails them."""
    def turned(spec, env):
        return ShelfExpert(ee_step=spec.ee_step * 4, rot_step=spec.rot_step * 4)

    def fixed(spec, env):
        return ShelfExpert(direction=(0.0, 1.0, 0.0), ee_step=spec.ee_step * 4, rot_step=spec.rot_step * 4)

    by_own_face = _broad_outcomes(turned, "shelf", 8)
    assert sum(by_own_face) >= 5
    assert sum(_broad_outcomes(fixed, "shelf", 8)) < sum(by_own_face)


def test_slot_expert_descends_into_broad_goal_boxes():
    def slot(spec, env):
        return SlotExpert(ee_step=spec.ee_step * 4, rot_step=spec.rot_step * 4)

    assert sum(_broad_outcomes(slot, "goal_box", 8)) >= 5


@pytest.mark.parametrize("kind, expert", [("shelf", ShelfExpert), ("goal_box", SlotExpert)])
def test_the_broad_experts_serve_the_kr16_too(kind, expert):
    """The KR16's broad worlds reach 1.71 m and its tool starts 30 degrees below horizontal;
    the same experts enter its shelves and boxes."""
    def make(spec, env):
        return expert(ee_step=spec.ee_step * 4, rot_step=spec.rot_step * 4)

    assert sum(_broad_outcomes(make, kind, 8, robot="kr16")) >= 5


def test_clone_into_a_broad_run_plays_the_goal_scene_of_its_kind(tmp_path):
    """A run in broad worlds clones the expert of one of the broad suite's goal scenes and
    says so in its report; the random worlds' kinds are refused, naming those it has."""
    from dataclasses import replace

    from rayreach.learning.demonstrations import CloneConfig, clone_into_checkpoint
    from rayreach.learning.train import TrainConfig, train, with_envs

    out = tmp_path / "broad"
    train(replace(with_envs(TrainConfig(), 4), workers=1, max_episode_steps=32, timesteps=256, suite="broad",
                  checkpoint_every=256), out)
    report = clone_into_checkpoint(out, "goal_box", CloneConfig(episodes=2, rounds=1, anchor_episodes=1,
                                                                eval_episodes=1), progress=False)
    assert report["suite"] == "broad" and report["kind"] == "goal_box"
    assert report["rounds"][0]["followed"] == "expert" and report["rounds"][0]["samples"] > 0
    with pytest.raises(ValueError, match="its kinds with an expert: shelf, goal_box"):
        clone_into_checkpoint(out, "goal_cover", CloneConfig(episodes=1), progress=False)
