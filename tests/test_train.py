"""Training smoke run: train, checkpoint, get killed, resume, save a policy rollout can load."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from rayreach.learning.curriculum import AugmentedGoalSize, ObstacleCurriculum
from rayreach.learning.bundles import CheckpointError, read_bundle_meta
from rayreach.learning.policy import load_policy
from rayreach.learning.export import train_command
from rayreach.learning.train import TrainState, append_curve

RAYREACH = [sys.executable, "-m", "rayreach.cli"]


def _run(*args: str, timeout: float = 240) -> subprocess.CompletedProcess:
    return subprocess.run([*RAYREACH, *args], capture_output=True, text=True, timeout=timeout)


def _train_args(out: Path, steps: int) -> list[str]:
    return ["train", "--robot", "ur5", "--timesteps", str(steps), "--envs", "2", "--workers", "1",
            "--out", str(out), "--checkpoint-every", "1024"]


def test_train_kill_resume_rollout(tmp_path):
    out = tmp_path / "run"
    process = subprocess.Popen([*RAYREACH, *_train_args(out, 6144)], stdout=subprocess.DEVNULL,
                               stderr=subprocess.DEVNULL)
    checkpoint = out / "checkpoint.zip"
    deadline = time.time() + 90
    while not checkpoint.exists() and time.time() < deadline and process.poll() is None:
        time.sleep(0.2)
    time.sleep(0.5)
    process.send_signal(signal.SIGKILL)  # no chance to save anything more
    process.wait(timeout=30)
    assert checkpoint.exists(), "no checkpoint was written before the kill"
    meta, norm = read_bundle_meta(checkpoint)
    killed_at = meta["timesteps"]
    assert meta["kind"] == "checkpoint" and 1024 <= killed_at < 6144
    assert norm is not None and norm["obs_mean"].shape == (142,)
    assert not (out / "model.zip").exists()

    assert meta["config"]["true_goal_share"] == 0.5
    done = _run(*_train_args(out, 6144), "--resume", "--true-goal-share", "0.25", "--obstacles", "2")
    assert done.returncode == 0, done.stderr[-2000:]
    final, _ = read_bundle_meta(out / "model.zip")
    assert final["kind"] == "model" and final["timesteps"] >= 6144
    assert final["config"]["true_goal_share"] == 0.25  # a resumed part may change the share
    assert final["config"]["obstacles"]["minimum"] == final["config"]["obstacles"]["maximum"] == 2
    assert final["state"]["obstacles"]["count"] == 2  # and hold the obstacle count
    assert final["state"]["episodes"] >= meta["state"]["episodes"]  # the curriculum went on
    with (out / "curve.csv").open() as handle:
        steps = [int(row["timesteps"]) for row in csv.DictReader(handle)]
    assert steps == sorted(steps) and steps[-1] >= 6144 and any(s > killed_at for s in steps)
    assert (out / "learning_curve.png").stat().st_size > 10_000

    rolled = _run("rollout", "--model", str(out / "model.zip"), "--scenario", "exp1", "--episodes", "1", "--json")
    assert rolled.returncode == 0, rolled.stderr[-2000:]
    summary = json.loads(rolled.stdout.strip().splitlines()[-1])
    assert {"success_rate", "collision_rate", "path_length_mean"} <= set(summary)

    policy = load_policy(out / "model.zip")  # frozen normalisation from the bundle
    _, norm_final = read_bundle_meta(out / "model.zip")
    obs = np.ones(142, dtype=np.float32)
    expected = np.clip((obs - norm_final["obs_mean"]) / np.sqrt(norm_final["obs_var"] + float(norm_final["epsilon"])),
                       -10, 10)
    np.testing.assert_allclose(policy.normalization(obs), expected, rtol=1e-6)
    assert policy.act(obs).shape == (6,)


def test_existing_checkpoint_needs_resume_and_bad_files_are_named(tmp_path):
    out = tmp_path / "run"
    out.mkdir()
    (out / "checkpoint.zip").write_bytes(b"not a zip at all")
    fresh = _run(*_train_args(out, 2048))
    assert fresh.returncode == 2 and "--resume" in fresh.stderr
    corrupt = _run(*_train_args(out, 2048), "--resume")
    assert corrupt.returncode == 2 and "corrupt" in corrupt.stderr
    with pytest.raises(CheckpointError, match="no model file"):
        load_policy(tmp_path / "missing.zip")


def test_resume_takes_new_reward_weights_and_refuses_another_robot(tmp_path):
    out = tmp_path / "run"
    first = _run(*_train_args(out, 1024))
    assert first.returncode == 0, first.stderr[-2000:]
    # nothing left to train: still a model, with the weights given to this part
    again = _run(*_train_args(out, 1024), "--resume", "--proximity-weight", "0", "--shield-weight", "-0.1")
    assert again.returncode == 0, again.stderr[-2000:]
    meta, _ = read_bundle_meta(out / "model.zip")
    assert (meta["config"]["proximity_weight"], meta["config"]["shield_weight"]) == (0.0, -0.1)
    assert meta["config"]["progress_weight"] == 10.0  # not given: the saved one
    other = _run("train", "--robot", "kr16", "--timesteps", "2048", "--envs", "2", "--workers", "1",
                 "--out", str(out), "--resume")
    assert other.returncode == 2 and "ur5" in other.stderr and "kr16" in other.stderr
    wrong_scene = _run("rollout", "--model", str(out / "model.zip"), "--scenario", "exp4")
    assert wrong_scene.returncode == 2 and "kr16" in wrong_scene.stderr
    assert os.path.exists(out / "model.zip")


def test_curve_from_an_older_version_gains_new_columns(tmp_path):
    path = tmp_path / "curve.csv"
    append_curve(path, {"timesteps": 1, "success_rate": 0.5})
    append_curve(path, {"timesteps": 2, "success_rate": 0.6, "true_success_rate": 0.1})
    append_curve(path, {"timesteps": 3, "success_rate": 0.7, "true_success_rate": 0.2})
    with path.open() as handle:
        rows = list(csv.DictReader(handle))
    assert [r["timesteps"] for r in rows] == ["1", "2", "3"]
    assert [r["true_success_rate"] for r in rows] == ["", "0.1", "0.2"]
    assert [r["success_rate"] for r in rows] == ["0.5", "0.6", "0.7"]


def test_train_state_keeps_true_size_outcomes_apart():
    state = TrainState(AugmentedGoalSize(), ObstacleCurriculum())
    for outcome, true_size in (("success", False), ("collision", True), ("success", True), ("timeout", False)):
        state.record(outcome, true_size)
    assert state.episodes == 4
    assert state.rate("success") == 0.5 and state.rate("success", true_size=True) == 0.5
    assert state.rate("collision", true_size=True) == 0.5
    again = TrainState.from_dict(state.to_dict())
    assert list(again.recent_true) == ["collision", "success"] and again.episodes == 4


def test_the_update_uses_no_more_threads_than_the_run_has_workers():
    from rayreach.learning.train import TrainConfig, update_threads

    assert update_threads(TrainConfig(workers=1), 2) == 1
    assert update_threads(TrainConfig(workers=2), 2) == 2
    assert update_threads(TrainConfig(workers=4), 2) == 2


def test_exported_command_keeps_the_flags_a_resume_keeps():
    base = {"robot": "kr16", "timesteps": 17100000, "envs": 32, "checkpoint_every": 250000,
            "obstacles": {"start": 1, "minimum": 0, "maximum": 3}}
    plain = train_command(base, "models/train-kr16")
    assert plain == ("rayreach train --robot kr16 --timesteps 17100000 --envs 32 --out models/train-kr16 "
                     "--checkpoint-every 250000 [--resume]")
    fixed = {**base, "acting_layers": True, "obstacles": {"start": 1, "minimum": 1, "maximum": 1}}
    assert train_command(fixed, "RUN").endswith("--checkpoint-every 250000 --acting-layers --obstacles 1 [--resume]")
