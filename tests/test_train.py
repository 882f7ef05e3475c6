"""Training: the smoke run (train, checkpoint, get killed, resume, save a policy rollout can
load), the recipes and their round trip through a bundle, the callback on sparse infos, a
resumed run of the default recipe and bench-train's record."""

from __future__ import annotations

import csv
import importlib.util
import json
import os
import signal
import subprocess
import sys
import time
import types
from dataclasses import asdict, replace
from pathlib import Path

import numpy as np
import pytest

from rayreach.learning.curriculum import AugmentedGoalSize, GoalSizeParams, ObstacleCurriculum
from rayreach.learning.bundles import CheckpointError, read_bundle_meta
from rayreach.learning.policy import load_policy
from rayreach.learning.export import train_command
from rayreach.learning.train import (ADAPTIVE_LR_BOUNDS, RECIPES, TrainConfig, TrainState, adapted_learning_rate,
                                     append_curve, bundle_meta, config_from_meta, env_config, recipe, with_envs)

RAYREACH = [sys.executable, "-m", "rayreach.cli"]


def _run(*args: str, timeout: float = 240) -> subprocess.CompletedProcess:
    return subprocess.run([*RAYREACH, *args], capture_output=True, text=True, timeout=timeout)


def _train_args(out: Path, steps: int) -> list[str]:
    return ["train", "--robot", "ur5", "--timesteps", str(steps), "--recipe", "baseline", "--envs", "2",
            "--workers", "1", "--out", str(out), "--checkpoint-every", "1024"]


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
    again = _run(*_train_args(out, 1024), "--resume", "--proximity-weight", "-0.05", "--shield-weight", "-0.1",
                 "--collision-weight", "-20", "--out-of-bounds-weight", "-30", "--checkpoint-every", "512")
    assert again.returncode == 0, again.stderr[-2000:]
    meta, _ = read_bundle_meta(out / "model.zip")
    assert meta["config"]["checkpoint_every"] == 512  # given again: a long resumed part is saved as often as asked
    assert (meta["config"]["proximity_weight"], meta["config"]["shield_weight"]) == (-0.05, -0.1)
    assert (meta["config"]["collision_weight"], meta["config"]["out_of_bounds_weight"]) == (-20.0, -30.0)
    rewards = env_config(config_from_meta(meta)).rewards
    assert (rewards.collision, rewards.out_of_bounds) == (-20.0, -30.0)
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
    assert plain == ("rayreach train --recipe baseline --robot kr16 --timesteps 17100000 --envs 32 "
                     "--out models/train-kr16 --checkpoint-every 250000 [--resume]")  # an old run: the baseline's
    assert "--recipe" not in train_command({**base, "recipe": "default", "envs": 256}, "RUN")
    assert train_command({**base, "recipe": "paper"}, "RUN").startswith("rayreach train --recipe paper --robot kr16")
    fixed = {**base, "acting_layers": True, "obstacles": {"start": 1, "minimum": 1, "maximum": 1}}
    assert train_command(fixed, "RUN").endswith("--checkpoint-every 250000 --acting-layers --obstacles 1 [--resume]")
    kr16 = {"starts": 2}  # the KR16's default recipe starts two seeds; a run saved before starts had one
    broad = {**base, "starts": 1, "recipe": "default", "suite": "broad", "decision_period": 4}  # one start in broad
    assert train_command(broad, "RUN").endswith(  # a broad run made before the recipe mixed the counts
        "--checkpoint-every 250000 --suite broad --obstacle-curriculum [--resume]")
    mixed = {**broad, "obstacles": {"start": 3, "minimum": 3, "maximum": 3, "mix": True}}
    assert train_command(mixed, "RUN").endswith("--checkpoint-every 250000 --suite broad [--resume]")
    assert train_command({**mixed, "obstacles": {**mixed["obstacles"], "mix": False}}, "RUN").endswith(
        "--suite broad --obstacles 3 [--resume]")
    # a default run made before the decision period decided every control step
    assert train_command({**base, **kr16, "recipe": "default"}, "RUN").endswith("--decision-period 1 [--resume]")
    assert train_command({**base, "recipe": "default"}, "RUN").endswith("--decision-period 1 --starts 1 [--resume]")
    base = {**base, **kr16, "decision_period": 4}
    slanted = asdict(replace(recipe("default", robot="kr16").observation, slanted=True))
    assert train_command({**base, "recipe": "default", "observation": slanted}, "RUN").endswith(
        "--checkpoint-every 250000 --slanted [--resume]")
    ur5 = {**base, "robot": "ur5", "starts": 1, "recipe": "default", "action_std_init": 0.3}
    no_tip_back = asdict(replace(recipe("default", robot="ur5").observation, tip_back=False))
    assert train_command({**ur5, "observation": no_tip_back}, "RUN").endswith(
        "--checkpoint-every 250000 --no-tip-back [--resume]")
    sight = asdict(replace(recipe("default", robot="ur5").observation, goal_sight=True))
    assert train_command({**ur5, "observation": sight}, "RUN").endswith("--checkpoint-every 250000 --goal-sight [--resume]")
    old_ur5 = {key: value for key, value in ur5.items() if key != "action_std_init"}  # saved before the UR5 took 0.3
    assert train_command(old_ur5, "RUN").endswith("--checkpoint-every 250000 --action-std-init 1 [--resume]")
    covers = {**base, "recipe": "default", "extra_kinds": ["goal_cover", "goal_cover"]}
    assert train_command(covers, "RUN").endswith("--checkpoint-every 250000 --extra-kinds goal_cover,goal_cover [--resume]")
    slow = {**base, "recipe": "default", "cover_speed": [0.03, 0.08]}
    assert train_command(slow, "RUN").endswith("--checkpoint-every 250000 --cover-speed 0.03,0.08 [--resume]")
    margin = {**base, "recipe": "default", "collision_margin": 0.02}
    assert train_command(margin, "RUN").endswith("--checkpoint-every 250000 --collision-margin 0.02 [--resume]")
    failures = {**base, "recipe": "default", "collision_weight": -40.0, "out_of_bounds_weight": -40.0}
    assert train_command(failures, "RUN").endswith(
        "--checkpoint-every 250000 --collision-weight -40 --out-of-bounds-weight -40 [--resume]")
    quiet = {**base, "recipe": "default", "action_std_init": 0.5}
    assert train_command(quiet, "RUN").endswith("--checkpoint-every 250000 --action-std-init 0.5 [--resume]")


# ---------------------------------------------------------------------- recipes and the batched path
def test_recipes_round_trip_through_bundle_meta_and_old_metas_read_as_baseline():
    state = TrainState(AugmentedGoalSize(), ObstacleCurriculum())
    state.learning_rate = 0.0015
    for name in RECIPES:
        config = recipe(name, robot="kr16", timesteps=1234)
        meta = json.loads(json.dumps(bundle_meta(config, state, 0, "checkpoint", 142)))  # as a bundle stores it
        assert config_from_meta(meta) == config
        assert TrainState.from_dict(meta["state"]).learning_rate == 0.0015
    old = bundle_meta(RECIPES["baseline"], state, 0, "checkpoint", 142)
    for new_field in ("vec_env", "lr_schedule", "desired_kl"):  # a run saved before these existed
        del old["config"][new_field]
    assert config_from_meta(old) == RECIPES["baseline"]
    assert TrainConfig().batched and not RECIPES["baseline"].batched
    from rayreach.cli import TRAIN_RECIPES  # the CLI names them without importing torch

    assert TRAIN_RECIPES == tuple(RECIPES)
    assert not replace(TrainConfig(), acting_layers=True, envs=32).batched  # the layers wrap each ReachEnv
    with pytest.raises(ValueError, match="--recipe baseline"):
        replace(TrainConfig(), acting_layers=True)  # 256 ReachEnvs would take some 14 GB
    with pytest.raises(ValueError, match="default, baseline"):
        recipe("fast")
    with pytest.raises(ValueError, match="batched, workers"):
        TrainConfig(vec_env="subproc")
    with pytest.raises(ValueError, match="constant, adaptive"):
        TrainConfig(lr_schedule="linear")
    with pytest.raises(ValueError, match="unknown world suite 'kitchen'; valid: random, broad"):
        TrainConfig(suite="kitchen")


def test_paper_recipe_is_the_papers_agent():
    from rayreach.learning.curriculum import GoalSizeParams

    paper = RECIPES["paper"]
    assert paper.observation.is_paper and not paper.normalize and paper.share_features
    assert (paper.progress_weight, paper.proximity_weight, paper.true_goal_share, paper.target_kl) == (0, 0, 0, None)
    assert (paper.gamma, paper.batch_size, paper.learning_rate, paper.lr_schedule, paper.clip_range,
            paper.max_episode_steps, paper.ent_coef, paper.vf_coef, paper.max_grad_norm, paper.gae_lambda) == (
        0.99, 256, 3e-4, "constant", 0.2, 1024, 0.0, 0.5, 0.5, 0.95)  # table "Hyperparameter for training"
    assert paper.goal == GoalSizeParams() and not paper.acting_layers
    assert not TrainConfig().observation.is_paper and RECIPES["baseline"].observation.is_paper


def test_with_envs_keeps_the_minibatch_where_a_rollout_holds_it():
    assert with_envs(RECIPES["baseline"], 2).batch_size == 256  # 2 x 256 steps: as before the recipes
    assert with_envs(TrainConfig(), 512).batch_size == 4096
    assert with_envs(TrainConfig(), 16).batch_size == 16 * 64  # one minibatch of the whole rollout
    with pytest.raises(ValueError, match="envs must be >= 1"):
        with_envs(TrainConfig(), 0)


def test_adaptive_learning_rate_follows_the_kl_within_its_bounds():
    assert adapted_learning_rate(1e-3, 0.05, 0.01) == pytest.approx(1e-3 / 1.5)
    assert adapted_learning_rate(1e-3, 0.001, 0.01) == pytest.approx(1.5e-3)
    assert adapted_learning_rate(1e-3, 0.01, 0.01) == 1e-3
    assert adapted_learning_rate(ADAPTIVE_LR_BOUNDS[1], 0.0, 0.01) == ADAPTIVE_LR_BOUNDS[1]
    assert adapted_learning_rate(ADAPTIVE_LR_BOUNDS[0], 1.0, 0.01) == ADAPTIVE_LR_BOUNDS[0]


class _Untouchable(dict):
    """The info of a world whose episode goes on: the callback must not even look at it."""

    def __getitem__(self, key):
        raise AssertionError("the callback read the info of a world whose episode goes on")

    get = keys = items = __contains__ = __iter__ = copy = __getitem__


def test_callback_reads_only_the_worlds_whose_episode_ended(tmp_path):
    from tqdm import tqdm

    from rayreach.learning.train import REWARD_TERMS, _make_callback

    calls = []
    venv = types.SimpleNamespace(num_envs=4, env_method=lambda name, *args: calls.append((name, *args)))
    model = types.SimpleNamespace(get_env=lambda: venv, logger=None, num_timesteps=4)
    config = TrainConfig(goal=GoalSizeParams(e_zeta=0, k=1, p_zeta=0.5))  # every success shrinks the goal
    state = TrainState(AugmentedGoalSize(config.goal), ObstacleCurriculum(config.obstacles))
    callback = _make_callback(config, state, tmp_path, total=100)
    callback.init_callback(model)
    callback.bar, callback.next_checkpoint, callback.next_validation = tqdm(disable=True), 10**9, 10**9
    terms = dict.fromkeys(REWARD_TERMS, 0.0)
    ended = {"is_success": True, "collision": False, "out_of_bounds": False, "distance": 0.005,
             "goal_tolerance": 0.1, "true_goal_episode": False, "episode_reward_terms": {**terms, "success": 10.0}}
    crashed = {**ended, "is_success": False, "collision": True, "goal_tolerance": 0.01, "true_goal_episode": True,
               "episode_reward_terms": {**terms, "collision": -10.0}}
    callback.update_locals({"dones": np.array([False, True, False, True]),
                            "infos": [_Untouchable(), ended, _Untouchable(), crashed]})
    assert callback.on_step()
    assert state.episodes == 2 and list(state.recent) == ["success", "collision"]
    assert list(state.recent_true) == ["collision"]  # played at rho_min
    assert state.goal.episode == 1  # the true-size episode does not feed the goal curriculum
    assert [t["success"] for t in callback.finished_terms] == [10.0, 0.0]
    assert calls == [("set_goal_tolerance", pytest.approx(0.09))]  # one push for the whole step
    callback.update_locals({"dones": np.zeros(4, dtype=bool), "infos": [_Untouchable()] * 4})
    assert callback.on_step() and state.episodes == 2


_CONTRACT_KEYS = ("is_success", "collision", "out_of_bounds", "distance", "goal_tolerance", "true_goal_episode",
                  "episode_reward_terms", "terminal_observation", "TimeLimit.truncated")


def _stand_in_batched_module() -> types.ModuleType:
    """STAND-IN for ``rayreach.env.batched``: ``ReachEnv``s in a DummyVecEnv behind
    ``BatchedReachEnv``'s contract (its signature; infos ``{}`` but at episode ends, and
    there only the contract's keys), so that the batched path of training is tested
    whatever state the real module is in."""
    from stable_baselines3.common.vec_env import DummyVecEnv

    from rayreach.env.reach import ReachEnv

    class BatchedReachEnv(DummyVecEnv):
        def __init__(self, robot, n_worlds, scenario="random", config=None, seed=None):
            super().__init__([lambda: ReachEnv(robot=robot, scenario=scenario, config=config)] * n_worlds)
            self.seed(seed)

        def step_wait(self):
            obs, rewards, dones, infos = super().step_wait()
            return obs, rewards, dones, [{k: info[k] for k in _CONTRACT_KEYS} if done else {}
                                         for info, done in zip(infos, dones)]

    module = types.ModuleType("rayreach.env.batched")
    module.BatchedReachEnv = BatchedReachEnv
    return module


def _small_default(**changes) -> TrainConfig:
    """The default recipe on 4 worlds, episodes of at most 32 steps (so that some end)."""
    return replace(with_envs(TrainConfig(), 4), workers=1, max_episode_steps=32, checkpoint_every=10**9, **changes)


_HAS_BATCHED = importlib.util.find_spec("rayreach.env.batched") is not None


@pytest.mark.parametrize("env", ["stand-in", pytest.param("real", marks=pytest.mark.skipif(
    not _HAS_BATCHED, reason="no rayreach.env.batched yet"))])
def test_default_recipe_trains_and_resumes_on_the_batched_path(tmp_path, monkeypatch, env):
    from rayreach.learning.train import train

    if env == "stand-in":
        monkeypatch.setitem(sys.modules, "rayreach.env.batched", _stand_in_batched_module())  # STAND-IN env
    out = tmp_path / "run"
    train(_small_default(timesteps=512, desired_kl=1.0), out)  # any KL of these updates is under half of 1.0
    meta, norm = read_bundle_meta(out / "checkpoint.zip")
    assert meta["timesteps"] == 512 and norm is not None
    assert (meta["config"]["vec_env"], meta["config"]["lr_schedule"]) == ("batched", "adaptive")
    adapted = meta["state"]["learning_rate"]
    assert adapted == pytest.approx(1.5e-3)  # the second rollout's end raised it once
    train(_small_default(timesteps=1024), out, resume=True)
    final, _ = read_bundle_meta(out / "model.zip")
    assert final["timesteps"] == 1024 and config_from_meta(final) == _small_default(timesteps=1024, desired_kl=1.0)
    assert final["state"]["episodes"] > meta["state"]["episodes"] > 0
    with (out / "curve.csv").open() as handle:
        rows = list(csv.DictReader(handle))
    assert [int(r["timesteps"]) for r in rows] == [256, 512, 768, 1024]
    assert float(rows[2]["learning_rate"]) == pytest.approx(adapted)  # the resumed part went on from it
    assert float(rows[-1]["reward_distance"]) < 0  # summed over whole episodes: episode_reward_terms
    if env == "real":  # the policy acts on the observation it was trained with
        from rayreach.evaluate.rollout import rollout
        from rayreach.learning.policy import load_policy

        assert load_policy(out / "model.zip").observation == TrainConfig().observation
        summary = rollout(out / "model.zip", "random", episodes=1, progress=False)
        assert summary.episodes == 1


@pytest.mark.skipif(not _HAS_BATCHED, reason="no rayreach.env.batched yet")
def test_a_policy_trained_in_broad_worlds_plays_them_and_is_refused_only_beyond_the_reach(tmp_path):
    """``suite="broad"`` trains in broad worlds; the policy knows it, and the DRL planner
    takes a goal in the arm's reach that lies outside the training box of random worlds."""
    from rayreach.evaluate.rollout import rollout
    from rayreach.learning.train import train
    from rayreach.planners import make_planner

    out = tmp_path / "broad"
    train(_small_default(timesteps=256, suite="broad"), out)
    meta, _ = read_bundle_meta(out / "model.zip")
    assert meta["config"]["suite"] == "broad" and load_policy(out / "model.zip").suite == "broad"
    assert load_policy(out / "model.zip").observation == TrainConfig().observation
    assert rollout(out / "model.zip", "broad", episodes=1, progress=False).by_kind  # broad kinds, read back
    start, beside = np.array([0.0, 0.5, 0.35]), np.array([[0.7, 0.0, 0.6]])  # out of the UR5's box, in its reach
    assert make_planner("drl", "ur5").refusal(start, beside).startswith("outside training")
    broad = make_planner("drl", "ur5", model=out / "model.zip")
    assert broad.refusal(start, beside) is None
    assert "outside the training workspace" in broad.refusal(start, np.array([[2.0, 0.0, 0.6]]))


def test_bench_train_times_both_recipes(tmp_path, monkeypatch):
    from rayreach.evaluate.bench_train import bench_train

    monkeypatch.setitem(sys.modules, "rayreach.env.batched", _stand_in_batched_module())  # STAND-IN env
    baseline = with_envs(replace(RECIPES["baseline"], n_steps=64, workers=1), 2)
    record = bench_train("ur5", 0.5, configs={"baseline": baseline, "default": _small_default()})
    assert set(record) >= {"robot", "seconds", "samples_per_s", "speedup", "phases"}
    assert set(record["samples_per_s"]) == {"baseline", "default"}
    for name, phases in record["phases"].items():
        assert phases["iterations"] >= 1 and phases["timed_s"] >= 0.5
        assert phases["samples"] == phases["iterations"] * (128 if name == "baseline" else 256)
        assert 0 < phases["collect_s"] + phases["update_s"] <= phases["timed_s"] + 0.05
    assert record["speedup"] == pytest.approx(record["samples_per_s"]["default"] / record["samples_per_s"]["baseline"],
                                              rel=1e-2)


@pytest.mark.expensive
@pytest.mark.skipif(not _HAS_BATCHED, reason="no rayreach.env.batched yet")
def test_bench_train_command_prints_its_record_last():
    done = _run("bench-train", "--robot", "ur5", "--seconds", "3", "--json", timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    record = json.loads(done.stdout.strip().splitlines()[-1])
    assert set(record) >= {"robot", "seconds", "samples_per_s", "speedup", "phases"}
    assert set(record["samples_per_s"]) == {"baseline", "default"} and record["seconds"] == 3


def test_train_command_line_sets_the_rays_beyond_the_recipes(tmp_path):
    """``--slanted`` and ``--no-tip-back`` change the observation a run trains with, and the
    policy it saves reads them back."""
    from rayreach.cli import main

    out = tmp_path / "kr16-slanted"
    assert main(["train", "--robot", "kr16", "--slanted", "--tip-back", "--timesteps", "256", "--envs", "4",
                 "--workers", "1", "--out", str(out)]) == 0
    observation = load_policy(out / "model.zip").observation
    assert observation.slanted and observation.tip_back
    assert observation == replace(recipe("default", robot="kr16").observation, slanted=True, tip_back=True)


def test_the_ur5s_default_recipe_starts_with_less_action_noise():
    """The UR5's default starts at 0.3 (``DEFAULT_BY_ROBOT``); the KR16's and the paper's at
    SB3's 1.0, and a starting value asked for wins over the robot's (the test below: the
    policy's noise is the value the run started with)."""
    ur5 = recipe("default", robot="ur5")
    assert ur5.action_std_init == 0.3
    assert recipe("default", robot="kr16").action_std_init == recipe("paper", robot="ur5").action_std_init == 1.0
    assert recipe("default", robot="ur5", action_std_init=0.5).action_std_init == 0.5


def test_a_run_starts_with_the_action_noise_asked_for_and_a_resume_keeps_its_own(tmp_path, capsys):
    """``--action-std-init`` sets the standard deviation of the new policy's action noise;
    a resumed part keeps the run's learned one and refuses another starting value by name."""
    import torch

    from rayreach.cli import main

    out = tmp_path / "run"
    args = ["train", "--robot", "ur5", "--timesteps", "256", "--envs", "4", "--workers", "1", "--out", str(out)]
    assert main([*args, "--action-std-init", "0.4", "--checkpoint-every", "1000000"]) == 0
    meta, _ = read_bundle_meta(out / "checkpoint.zip")
    assert meta["config"]["action_std_init"] == 0.4
    policy = load_policy(out / "checkpoint.zip").model.policy
    assert torch.allclose(policy.log_std.exp(), torch.full((6,), 0.4), atol=0.05)  # one update moved it a little
    assert main([*args, "--timesteps", "512", "--resume", "--action-std-init", "1.0"]) == 2
    assert "this run started with 0.4" in capsys.readouterr().err
    with pytest.raises(ValueError, match="must be > 0"):
        TrainConfig(action_std_init=0.0)


def test_a_resumed_part_discounts_its_returns_by_a_new_gamma(tmp_path):
    """SB3 keeps a loaded model's discount; a part resumed with another computes its returns,
    advantages and reward normalisation with the new one, and the run's command names it."""
    from stable_baselines3.common.callbacks import BaseCallback

    from rayreach.learning.train import train

    seen = []

    class Discounts(BaseCallback):
        def _on_rollout_end(self) -> None:
            seen.append((self.model.gamma, self.model.rollout_buffer.gamma, self.model.get_vec_normalize_env().gamma))

        def _on_step(self) -> bool:
            return True

    out = tmp_path / "run"
    train(_small_default(timesteps=256), out, callbacks=[Discounts()])
    train(_small_default(timesteps=512), out, resume=True, resume_overrides={"gamma": 0.995}, callbacks=[Discounts()])
    assert seen[0] == (0.99, 0.99, 0.99) and seen[-1] == (0.995, 0.995, 0.995)
    meta, _ = read_bundle_meta(out / "model.zip")
    assert meta["config"]["gamma"] == 0.995 and " --gamma 0.995 " in train_command(meta["config"], "RUN")


def test_extra_kinds_are_drawn_beside_the_robots_and_survive_a_resume():
    from rayreach.learning.train import env_config
    from rayreach.robots import UR5

    config = recipe("default", robot="ur5", extra_kinds=("goal_cover", "goal_cover"))
    kinds = env_config(config).random_world.kinds
    assert kinds == UR5.training_kinds + ("goal_cover", "goal_cover")
    assert kinds.count("goal_cover") == 3 * UR5.training_kinds.count("goal_cover")
    assert env_config(recipe("default", robot="ur5")).random_world.kinds is None  # the robot's own
    state = TrainState(AugmentedGoalSize(), ObstacleCurriculum())
    meta = json.loads(json.dumps(bundle_meta(config, state, 0, "checkpoint", 142)))
    assert config_from_meta(meta) == config
    with pytest.raises(ValueError, match="unknown obstacle kind.*lid.*known: plate, moving_plate"):
        recipe("default", extra_kinds=("lid",))


def test_a_cover_speed_reaches_the_training_worlds_and_survives_a_resume():
    from rayreach.learning.train import env_config

    config = recipe("default", robot="ur5", cover_speed=(0.03, 0.08))
    world = env_config(config).random_world
    assert world.cover_speed == (0.03, 0.08) and world.speed == (0.05, 0.2)  # moving plates keep theirs
    assert env_config(recipe("default", robot="ur5")).random_world.cover_speed is None
    state = TrainState(AugmentedGoalSize(), ObstacleCurriculum())
    meta = json.loads(json.dumps(bundle_meta(config, state, 0, "checkpoint", 142)))
    assert config_from_meta(meta) == config
    with pytest.raises(ValueError, match=r"cover_speed must be \(low, high\).*got \(0.2, 0.1\)"):
        recipe("default", cover_speed=(0.2, 0.1))


def test_a_collision_margin_reaches_the_training_worlds_and_survives_a_resume():
    from rayreach.learning.train import env_config

    config = recipe("default", robot="ur5", collision_margin=0.02)
    assert env_config(config).collision_margin == 0.02
    assert env_config(recipe("default", robot="ur5")).collision_margin == 0.0  # evaluation's: touching
    state = TrainState(AugmentedGoalSize(), ObstacleCurriculum())
    meta = json.loads(json.dumps(bundle_meta(config, state, 0, "checkpoint", 142)))
    assert config_from_meta(meta) == config
    del meta["config"]["collision_margin"]  # a run saved before the margin
    assert config_from_meta(meta).collision_margin == 0.0
    with pytest.raises(ValueError, match=r"collision_margin must be in \[0, 0.1\) m, got -0.01"):
        recipe("default", collision_margin=-0.01)


def test_an_obstacle_mix_puts_the_worlds_at_one_to_n_obstacles(tmp_path, monkeypatch, capsys):
    """``--obstacle-mix 3``: of six batched worlds two train at each of one, two and three
    obstacles, and the run's command says so."""
    from rayreach.cli import main
    from rayreach.env.batched import BatchedReachEnv

    pushed: dict[int, int] = {}
    original = BatchedReachEnv.set_n_obstacles

    def spy(self, n, indices=None):
        original(self, n, indices)
        pushed.update({i: int(n) for i in self._get_indices(indices)})

    monkeypatch.setattr(BatchedReachEnv, "set_n_obstacles", spy)
    out = tmp_path / "mix"
    assert main(["train", "--robot", "ur5", "--obstacle-mix", "3", "--timesteps", "256", "--envs", "6",
                 "--workers", "1", "--out", str(out), "--checkpoint-every", "256"]) == 0
    assert pushed == {0: 1, 1: 2, 2: 3, 3: 1, 4: 2, 5: 3}
    meta, _ = read_bundle_meta(out / "model.zip")
    assert meta["config"]["obstacles"]["mix"] and meta["state"]["obstacles"]["count"] == 3
    assert " --obstacle-mix 3 " in train_command(meta["config"], "RUN")
    assert main(["train", "--robot", "ur5", "--obstacle-mix", "3", "--obstacles", "2", "--out", str(tmp_path / "x")]) == 2
    assert "give one" in capsys.readouterr().err


def test_the_obstacle_curriculum_flag_undoes_the_broad_recipes_mix(tmp_path, monkeypatch, capsys):
    """A broad run by the recipe before the mix is repeated by the command its bundle prints."""
    from rayreach.cli import main
    from rayreach.learning import clone_stage
    from rayreach.learning.curriculum import ObstacleParams

    got = {}

    def capture(config, out, **_):
        got["config"] = config
        raise SystemExit(0)

    monkeypatch.setattr(clone_stage, "train_with_clone", capture)
    with pytest.raises(SystemExit):
        main(["train", "--robot", "ur5", "--suite", "broad", "--obstacle-curriculum", "--out", str(tmp_path / "c")])
    assert got["config"].obstacles == ObstacleParams() and got["config"].suite == "broad"
    assert " --obstacle-curriculum " in train_command(asdict(got["config"]), "RUN")
    assert main(["train", "--robot", "ur5", "--obstacle-curriculum", "--obstacle-mix", "2",
                 "--out", str(tmp_path / "x")]) == 2
    assert "--obstacle-mix and --obstacle-curriculum" in capsys.readouterr().err


def test_a_resumed_part_steps_another_number_of_worlds_through_the_acting_layers(tmp_path):
    """A run of the default recipe's batched worlds may go on through the acting layers, which
    step one ``ReachEnv`` per world and take 64 at most: the resumed part takes the new count,
    sizes its rollout and minibatch by it, and its command names both."""
    from stable_baselines3.common.callbacks import BaseCallback

    from rayreach.learning.train import train

    seen = []

    class Rollouts(BaseCallback):
        def _on_rollout_end(self) -> None:
            seen.append((self.model.n_envs, self.model.rollout_buffer.n_envs, self.model.batch_size))

        def _on_step(self) -> bool:
            return True

    out = tmp_path / "run"
    train(_small_default(timesteps=256), out, callbacks=[Rollouts()])
    assert seen[-1] == (4, 4, 256)
    with pytest.raises(ValueError, match="give it 64 or fewer"):
        train(_small_default(timesteps=512), out, resume=True, resume_overrides={"envs": 65, "acting_layers": True})
    train(_small_default(timesteps=512), out, resume=True, resume_overrides={"envs": 2, "acting_layers": True},
          callbacks=[Rollouts()])
    assert seen[-1] == (2, 2, 128)  # 2 worlds x 64 steps: one minibatch of the whole rollout
    meta, _ = read_bundle_meta(out / "model.zip")
    assert (meta["config"]["envs"], meta["config"]["batch_size"], meta["config"]["acting_layers"]) == (2, 128, True)
    assert meta["timesteps"] >= 512
    assert " --envs 2 " in train_command(meta["config"], "RUN") + " "
    from rayreach.cli import main

    # a later part needs no --envs again: the run's own 2 worlds, not the recipe's 256, meet the layers' bound
    assert main(["train", "--robot", "ur5", "--out", str(out), "--resume", "--acting-layers", "--timesteps", "640",
                 "--workers", "1"]) == 0
    meta, _ = read_bundle_meta(out / "model.zip")
    assert (meta["config"]["envs"], meta["timesteps"]) == (2, 640)
