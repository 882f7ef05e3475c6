"""Shelf demonstrations: the scripted expert enters every compartment of exp4..exp7, and
cloning it into a checkpoint keeps the run resumable."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pybullet as p
import pytest

from rayreach.demonstrations import ShelfExpert
from rayreach.env import ReachEnv
from rayreach.policy import read_bundle_meta


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


@pytest.mark.parametrize("name", ["exp4", "exp5", "exp6", "exp7"])
def test_expert_reaches_each_compartment_goal_without_touching_the_shelf(name):
    """Checked against PyBullet's own closest points at every step, not the env's flag."""
    env = ReachEnv(robot="kr16", scenario=name)
    expert = ShelfExpert()
    try:
        obs, info = env.reset(seed=0)
        scene = env.scene
        done, clearance, advanced_tilted = False, np.inf, False
        while not done:
            action = expert.action(obs, env.ee_rot[:, 2])
            if action[1] > 0 and env.ee_rot[1, 2] < np.cos(0.03):
                advanced_tilted = True
            obs, _, terminated, truncated, info = env.step(action)
            done = terminated or truncated
            for body in scene._obstacle_ids:
                for point in p.getClosestPoints(scene.robot, body, 0.05, physicsClientId=scene.client):
                    clearance = min(clearance, point[8])
        assert info["is_success"] and not info["collision"]
        assert info["distance"] < 0.01
        assert clearance > 0.0
        assert not advanced_tilted
        assert env.steps < 300
    finally:
        env.close()


def test_clone_shelf_keeps_the_step_count_and_adds_its_time(tmp_path):
    rayreach = [sys.executable, "-m", "rayreach.cli"]
    out = tmp_path / "run"
    trained = subprocess.run([*rayreach, "train", "--robot", "kr16", "--timesteps", "1024", "--envs", "2",
                              "--workers", "1", "--out", str(out), "--checkpoint-every", "1024"],
                             capture_output=True, text=True, timeout=240)
    assert trained.returncode == 0, trained.stderr[-2000:]
    before, _ = read_bundle_meta(out / "checkpoint.zip")
    cloned = subprocess.run([*rayreach, "clone-shelf", "--run", str(out), "--episodes", "2", "--rounds", "2",
                             "--anchor-episodes", "1", "--eval-episodes", "1"],
                            capture_output=True, text=True, timeout=240)
    assert cloned.returncode == 0, cloned.stderr[-2000:]
    after, norm = read_bundle_meta(out / "checkpoint.zip")
    assert after["kind"] == "checkpoint" and after["timesteps"] == before["timesteps"]
    assert after["state"]["wall_time"] > before["state"]["wall_time"]
    assert norm is not None and norm["obs_mean"].shape == (142,)
    report = json.loads((out / "clone.json").read_text())
    assert [r["followed"] for r in report["rounds"]] == ["expert", "cloned actor"]
    assert report["rounds"][0]["success_rate"] == 1.0  # the expert itself
    resumed = subprocess.run([*rayreach, "train", "--robot", "kr16", "--timesteps", "2048", "--envs", "2",
                              "--workers", "1", "--out", str(out), "--checkpoint-every", "1024", "--resume"],
                             capture_output=True, text=True, timeout=240)
    assert resumed.returncode == 0, resumed.stderr[-2000:]
    wrong = subprocess.run([*rayreach, "clone-shelf", "--run", str(out / "model.zip")], capture_output=True,
                           text=True, timeout=60)
    assert wrong.returncode == 2 and "checkpoint" in wrong.stderr
