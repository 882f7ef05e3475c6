"""Several seeds started side by side, the best continued: the choice goes by each start's
last validation, the chosen start's run is the one that continues (its seed, curve and
checkpoint), and an interrupted run resumes the starts or the continuation."""

from __future__ import annotations

import csv
import json
import sys
from dataclasses import asdict, replace

import pytest

from rayreach.learning import selection, starts
from rayreach.learning.bundles import CheckpointError, read_bundle_meta
from rayreach.learning.export import train_command
from rayreach.learning.sweep import Trial, run_trial
from rayreach.learning.train import TrainConfig, recipe, with_envs

from test_train import _stand_in_batched_module


def _small(**changes) -> TrainConfig:
    settings = {"workers": 2, "max_episode_steps": 32, "checkpoint_every": 10**9, "validate_every": 256,
                "validate_worlds": 3, "starts": 2, "start_decisions": 256}
    return replace(with_envs(TrainConfig(), 4), **{**settings, **changes})


def _scored_by_seed(scores: dict[int, float], seen: list):
    """A stand-in for ``selection.validate`` whose score depends on the judged checkpoint's seed."""
    def validate(checkpoint, robot, suite, worlds):
        meta = read_bundle_meta(checkpoint)[0]
        seed = meta["config"]["seed"]
        seen.append((seed, meta["timesteps"]))
        return {"success_rate": scores[seed], "collision_rate": 0.0, "out_of_bounds_rate": 0.0,
                "timeout_rate": 1.0 - scores[seed], "score": scores[seed], "worlds": worlds, "obstacles": 2}
    return validate


def _one_after_another(trials, command, stop_after: int | None = None):
    """The starts in this process (where the stand-ins live); ``stop_after`` trials, a Ctrl-C."""
    for i, trial in enumerate(trials):
        if stop_after is not None and i == stop_after:
            raise KeyboardInterrupt
        run_trial(trial, command=command)
    return {}


def test_the_best_start_continues_with_its_own_seed_curve_and_checkpoint(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "rayreach.env.batched", _stand_in_batched_module())
    seen: list = []
    monkeypatch.setattr(selection, "validate", _scored_by_seed({3: 0.2, 4: 0.7}, seen))
    out = tmp_path / "run"
    config = _small(seed=3, timesteps=768)
    with pytest.raises(KeyboardInterrupt):  # stopped after the first start
        starts.train_with_starts(config, out, runner=lambda t, c: _one_after_another(t, c, stop_after=1))
    with pytest.raises(CheckpointError, match="pass --resume"):
        starts.train_with_starts(config, out, runner=_one_after_another)
    model = starts.train_with_starts(config, out, resume=True, runner=_one_after_another)

    first = [s for s in seen if s[1] == 256]
    assert first == [(3, 256), (4, 256)]  # each start judged once at its end; seed 3 was not run again
    report = json.loads((out / starts.STARTS_JSON).read_text())
    assert report["chosen_seed"] == 4 and [s["score"] for s in report["starts"]] == [0.2, 0.7]
    meta, _ = read_bundle_meta(model)
    assert meta["config"]["seed"] == 4 and meta["timesteps"] == 768
    assert meta["config"]["workers"] == 2 and meta["config"]["validate_every"] == 256
    assert meta["state"]["best"]["timesteps"] == 256  # what the chosen start scored, kept to beat
    with (out / "curve.csv").open() as handle:
        steps = [int(r["timesteps"]) for r in csv.DictReader(handle)]
    with (out / "starts" / "seed-4" / "curve.csv").open() as handle:
        chosen_steps = [int(r["timesteps"]) for r in csv.DictReader(handle)]
    assert steps[:len(chosen_steps)] == chosen_steps and steps[-1] == 768
    assert [s for s in seen if s[1] > 256] == [(4, 512), (4, 768)]  # the continuation is seed 4's run

    again = len(seen)
    starts.train_with_starts(replace(config, timesteps=1024), out, resume=True,
                             runner=lambda t, c: pytest.fail("the choice is made: no start runs again"))
    assert read_bundle_meta(out / "model.zip")[0]["timesteps"] == 1024 and len(seen) == again + 1


def test_the_choice_goes_by_score_a_tie_to_the_lower_seed_and_skips_failed_starts():
    results = [starts.StartResult(5, 0.4), starts.StartResult(6, None, error="exit code 1"),
               starts.StartResult(7, 0.4), starts.StartResult(8, 0.3)]
    assert starts.choose(results).seed == 5
    with pytest.raises(RuntimeError, match="seed 6: exit code 1; seed 7: no validation"):
        starts.choose([results[1], starts.StartResult(7, None, error="no validation on record")])


def test_each_start_gets_its_seed_a_share_of_the_cores_and_a_validation_at_its_end(tmp_path):
    trials = starts.plan_starts(_small(seed=10, workers=2, starts=3, validate_every=0, start_decisions=1000), tmp_path)
    assert [t.config.seed for t in trials] == [10, 11, 12]
    assert [t.out for t in trials] == [tmp_path / "starts" / f"seed-{s}" for s in (10, 11, 12)]
    assert {(t.config.workers, t.config.timesteps, t.config.validate_every) for t in trials} == {(1, 1000, 1000)}
    longer = starts.plan_starts(_small(validate_every=5000, start_decisions=1000), tmp_path)
    assert {t.config.validate_every for t in longer} == {1000}


def test_settings_are_checked_and_the_kr16_starts_two():
    with pytest.raises(ValueError, match="starts and start_decisions must be >= 1"):
        TrainConfig(starts=0)
    assert recipe("default", robot="kr16").starts == 2
    assert recipe("default", robot="ur5").starts == recipe("paper", robot="kr16").starts == 1
    assert "--starts" not in train_command(asdict(recipe("default", robot="kr16")), "runs/x")
    assert "--starts 1 " in train_command(asdict(recipe("default", robot="kr16", starts=1)), "runs/x")


def test_starts_run_in_processes_of_their_own_and_a_failed_one_is_named(tmp_path):
    good = replace(with_envs(TrainConfig(), 2), workers=1, timesteps=128, max_episode_steps=32,
                   checkpoint_every=10**9, validate_every=0)
    trials = [Trial("seed-0", good, tmp_path / "seed-0"), Trial("seed-1", replace(good, robot="nope"), tmp_path / "seed-1")]
    errors = starts.run_in_processes(trials, "test")
    assert list(errors) == ["seed-1"] and "train.log" in errors["seed-1"]
    assert read_bundle_meta(tmp_path / "seed-0" / "model.zip")[0]["timesteps"] >= 128
    assert "nope" in (tmp_path / "seed-1" / "train.log").read_text()
