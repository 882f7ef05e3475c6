"""Several seeds started side by side, the best continued: each start is judged on the
checkpoint it ended on, the chosen start's run is the one that continues (its seed, curve,
checkpoint and the run's own settings), and an interrupted run resumes the starts or the
continuation."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from dataclasses import asdict, replace
from pathlib import Path

import pytest

from rayreach.learning import selection, starts
from rayreach.learning.bundles import CheckpointError, read_bundle_meta
from rayreach.learning.export import train_command
from rayreach.learning.sweep import Trial, run_trial
from rayreach.learning.train import TrainConfig, recipe, train, with_envs

from test_train import _stand_in_batched_module


def _small(**changes) -> TrainConfig:
    settings = {"workers": 2, "max_episode_steps": 32, "checkpoint_every": 10**9, "validate_every": 512,
                "validate_worlds": 3, "starts": 2, "start_decisions": 256}
    return replace(with_envs(TrainConfig(n_steps=16), 4), **{**settings, **changes})  # 64 decisions a rollout


def _scored_by_seed(scores: dict[int, float | BaseException], seen: list):
    """A stand-in for ``selection.validate`` whose score (or exception) depends on the judged
    checkpoint's seed."""
    def validate(checkpoint, robot, suite, worlds):
        meta = read_bundle_meta(checkpoint)[0]
        seed = meta["config"]["seed"]
        seen.append((seed, meta["timesteps"]))
        if isinstance(scores[seed], BaseException):
            raise scores[seed]
        return {"success_rate": scores[seed], "collision_rate": 0.0, "out_of_bounds_rate": 0.0,
                "timeout_rate": 1.0 - scores[seed], "score": scores[seed], "worlds": worlds, "obstacles": 2}
    return validate


def _here(trials, command):
    """The starts one after another in this process, where the stand-ins live."""
    for trial in trials:
        run_trial(trial, command=command)
    return {}


def _stopped_halfway(trials, command):
    """The first start whole, the second to half its decisions, then a Ctrl-C."""
    run_trial(trials[0], command=command)
    train(replace(trials[1].config, timesteps=128), trials[1].out)
    raise KeyboardInterrupt


def test_the_best_start_continues_with_its_own_seed_curve_and_checkpoint(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "rayreach.env.batched", _stand_in_batched_module())
    seen: list = []
    monkeypatch.setattr(selection, "validate", _scored_by_seed({3: 0.2, 4: 0.7}, seen))
    out = tmp_path / "run"
    config = _small(seed=3, timesteps=1024, checkpoint_every=10**8)
    with pytest.raises(KeyboardInterrupt):
        starts.train_with_starts(config, out, runner=_stopped_halfway)
    with pytest.raises(CheckpointError, match="pass --resume"):
        starts.train_with_starts(config, out, runner=_here)
    model = starts.train_with_starts(config, out, resume=True, runner=_here)

    # neither start validated by itself (every 512 decisions): each was judged on its end
    assert seen[:2] == [(3, 256), (4, 256)]
    seed4 = read_bundle_meta(out / "starts" / "seed-4" / "model.zip")[0]
    assert seed4["state"]["episodes"] > 0 and seed4["timesteps"] == 256  # resumed from 128, not started again
    report = json.loads((out / starts.STARTS_JSON).read_text())
    assert report["chosen_seed"] == 4 and [s["score"] for s in report["starts"]] == [0.2, 0.7]
    assert report["wall_time_s"] == max(s["wall_time_s"] for s in report["starts"])
    meta, _ = read_bundle_meta(model)
    assert meta["config"]["seed"] == 4 and meta["timesteps"] == 1024
    # the run's own settings, not the start's share of the cores or its length
    assert (meta["config"]["workers"], meta["config"]["validate_every"], meta["config"]["checkpoint_every"]) == \
        (2, 512, 10**8)
    assert meta["wall_time_s"] > report["wall_time_s"]
    with (out / "curve.csv").open() as handle:
        steps = [int(r["timesteps"]) for r in csv.DictReader(handle)]
    with (out / "starts" / "seed-4" / "curve.csv").open() as handle:
        chosen_steps = [int(r["timesteps"]) for r in csv.DictReader(handle)]
    assert steps[:len(chosen_steps)] == chosen_steps and steps[-1] == 1024
    assert seen[2:] == [(4, 512), (4, 1024)]  # the continuation is seed 4's run
    assert [r["timesteps"] for r in selection.read_validation(out)] == [256, 512, 1024]

    starts.train_with_starts(replace(config, timesteps=1280), out, resume=True,
                             runner=lambda t, c: pytest.fail("the choice is made: no start runs again"))
    assert read_bundle_meta(out / "model.zip")[0]["timesteps"] == 1280


def test_a_start_is_judged_on_the_checkpoint_it_ended_on(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "rayreach.env.batched", _stand_in_batched_module())
    seen: list = []
    scores: dict = {0: 0.4}
    monkeypatch.setattr(selection, "validate", _scored_by_seed(scores, seen))
    trial = starts.plan_starts(_small(validate_every=128, starts=1), tmp_path)[0]
    train(replace(trial.config, timesteps=128), trial.out)  # validated at 128
    scores[0] = RuntimeError("judge failed")
    run_trial(trial)  # its validation at 256 fails and is skipped
    assert [r["timesteps"] for r in selection.read_validation(trial.out)] == [128]
    scores[0] = 0.6
    result = starts.judge(trial)
    assert (result.score, result.row["timesteps"]) == (0.6, 256) and seen[-1] == (0, 256)
    assert [r["timesteps"] for r in selection.read_validation(trial.out)] == [128, 256]
    judged = len(seen)
    assert starts.judge(trial).score == 0.6 and len(seen) == judged  # on record now: not made again


def test_the_choice_goes_by_score_and_a_tie_to_the_lower_seed():
    def result(seed, score):
        return starts.StartResult(seed, {"score": score}, 1.0)

    assert starts.choose([result(5, 0.4), result(6, 0.3), result(7, 0.4)]).seed == 5
    assert starts.choose([result(5, 0.4), result(6, 0.5)]).seed == 6


def test_each_start_gets_its_seed_and_a_share_of_the_cores(tmp_path):
    trials = starts.plan_starts(_small(seed=10, workers=2, starts=3, start_decisions=1000), tmp_path)
    assert [t.config.seed for t in trials] == [10, 11, 12]
    assert [t.out for t in trials] == [tmp_path / "starts" / f"seed-{s}" for s in (10, 11, 12)]
    assert {(t.config.workers, t.config.timesteps, t.config.validate_every) for t in trials} == {(1, 1000, 512)}


def test_a_run_no_longer_than_a_start_trains_once_and_part_settings_wait_for_the_choice(tmp_path, monkeypatch):
    called = []
    monkeypatch.setattr(starts, "train", lambda config, out, **kw: called.append((config.timesteps, kw)))
    starts.train_with_starts(_small(timesteps=256), tmp_path / "a", runner=lambda t, c: pytest.fail("no starts"))
    assert called == [(256, {"resume": False, "command": "", "resume_overrides": None})]
    with pytest.raises(ValueError, match="freeze_features apply to one part"):
        starts.train_with_starts(_small(timesteps=1024), tmp_path / "b", freeze_features=True, critic_warmup=0)


def test_settings_are_checked_and_the_kr16_starts_two():
    with pytest.raises(ValueError, match="starts and start_decisions must be >= 1"):
        TrainConfig(starts=0)
    assert recipe("default", robot="kr16").starts == 2
    assert recipe("default", robot="ur5").starts == recipe("paper", robot="kr16").starts == 1
    assert "--start" not in train_command(asdict(recipe("default", robot="kr16")), "runs/x")
    assert "--starts 1 " in train_command(asdict(recipe("default", robot="kr16", starts=1)), "runs/x")
    three = asdict(recipe("default", robot="ur5", starts=3, start_decisions=10**6))
    assert "--starts 3 --start-decisions 1000000 " in train_command(three, "runs/x")


def test_starts_run_in_processes_of_their_own_and_a_failed_one_is_named(tmp_path):
    good = replace(with_envs(TrainConfig(), 2), workers=1, timesteps=128, max_episode_steps=32,
                   checkpoint_every=10**9, validate_every=0)
    trials = [Trial("seed-0", good, tmp_path / "seed-0"), Trial("seed-1", replace(good, robot="nope"), tmp_path / "seed-1")]
    errors = starts.run_in_processes(trials, "test")
    assert list(errors) == ["seed-1"] and "train.log" in errors["seed-1"]
    assert read_bundle_meta(tmp_path / "seed-0" / "model.zip")[0]["timesteps"] >= 128
    assert "nope" in (tmp_path / "seed-1" / "train.log").read_text()


def test_a_sigterm_to_the_run_makes_each_start_write_its_checkpoint(tmp_path):
    script = f"""
from dataclasses import replace
from pathlib import Path
from rayreach.learning.starts import run_in_processes
from rayreach.learning.sweep import Trial
from rayreach.learning.train import TrainConfig, with_envs
config = replace(with_envs(TrainConfig(), 2), workers=1, timesteps=10**7, max_episode_steps=32,
                 checkpoint_every=10**9, validate_every=0)
out = Path({str(tmp_path)!r})
run_in_processes([Trial("seed-0", config, out / "seed-0"), Trial("seed-1", replace(config, seed=1), out / "seed-1")], "")
"""
    proc = subprocess.Popen([sys.executable, "-c", script], stderr=subprocess.PIPE, text=True)
    curves = [tmp_path / f"seed-{s}" / "curve.csv" for s in (0, 1)]
    deadline = time.monotonic() + 120
    while not all(c.exists() for c in curves) and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.5)
    os.kill(proc.pid, signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode != 0 and "resume with --resume" in err
    for seed in (0, 1):
        meta = read_bundle_meta(tmp_path / f"seed-{seed}" / "checkpoint.zip")[0]
        assert 0 < meta["timesteps"] < 10**7
        assert not (tmp_path / f"seed-{seed}" / "model.zip").exists()
