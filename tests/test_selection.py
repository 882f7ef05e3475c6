"""Choosing a run's checkpoint on validation worlds: the best so far is kept as best.zip,
survives a resume, and is what a run directory exports; the validation itself plays the
checkpoint alone on the robot's task worlds of the validation split."""

from __future__ import annotations

import csv
import json
import sys
from pathlib import Path
from dataclasses import asdict, replace

import pytest

from rayreach.learning import selection
from rayreach.learning.bundles import CheckpointError, read_bundle_meta
from rayreach.learning.export import export_bundle, run_bundle, train_command
from rayreach.learning.train import TrainConfig, recipe, train, with_envs

from test_train import _stand_in_batched_module

SHIPPED_UR5 = Path(__file__).parents[1] / "models" / "ur5.zip"


def _small(**changes) -> TrainConfig:
    settings = {"workers": 1, "max_episode_steps": 32, "checkpoint_every": 10**9, "validate_every": 256,
                "validate_worlds": 3}
    return replace(with_envs(TrainConfig(), 4), **{**settings, **changes})


def _scripted(scores: dict[int, float | BaseException], seen: list):
    """A stand-in for ``selection.validate`` whose score (or exception) at each step count is
    given; it reads the step count from the checkpoint, so a verdict belongs to the file it judged."""
    def validate(checkpoint, robot, suite, worlds):
        steps = read_bundle_meta(checkpoint)[0]["timesteps"]
        seen.append((steps, robot, suite, worlds))
        if isinstance(scores[steps], BaseException):
            raise scores[steps]
        return {"success_rate": scores[steps], "collision_rate": 0.0, "out_of_bounds_rate": 0.0,
                "timeout_rate": 1.0 - scores[steps], "score": scores[steps], "worlds": worlds, "obstacles": 2}
    return validate


def test_the_best_checkpoint_is_kept_and_survives_a_resume(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "rayreach.env.batched", _stand_in_batched_module())
    seen: list = []
    monkeypatch.setattr(selection, "validate", _scripted({256: 0.2, 512: 0.5, 768: 0.5, 1024: 0.4, 1280: 0.45}, seen))
    out = tmp_path / "run"
    train(_small(timesteps=768), out)
    assert [s[0] for s in seen] == [256, 512, 768] and seen[0][1:] == ("ur5", "random", 3)
    best, _ = read_bundle_meta(out / selection.BEST)
    assert best["timesteps"] == 512  # the tie at 768 keeps the earlier checkpoint
    assert best["state"]["best"]["score"] == 0.5
    assert run_bundle(out) == out / selection.BEST

    # every 512 from here: 1024 in the run, 1280 (its last rollout's end) once it ends
    train(_small(timesteps=1280), out, resume=True, resume_overrides={"validate_every": 512})
    assert [s[0] for s in seen] == [256, 512, 768, 1024, 1280]
    assert read_bundle_meta(out / selection.BEST)[0]["timesteps"] == 512  # the resumed part knew what to beat
    final, _ = read_bundle_meta(out / "model.zip")
    assert final["state"]["best"]["timesteps"] == 512
    with (out / selection.VALIDATION_CSV).open() as handle:
        rows = list(csv.DictReader(handle))
    assert [int(r["timesteps"]) for r in rows] == [s[0] for s in seen]
    assert (out / "learning_curve.png").stat().st_size > 10_000

    _, info = export_bundle(out, tmp_path / "ship" / "ur5.zip")
    shipped = json.loads(info.read_text())
    assert shipped["timesteps"] == 512 and shipped["validation"]["score"] == 0.5


def test_an_interrupted_validation_is_made_on_resume_and_a_failed_one_is_skipped(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "rayreach.env.batched", _stand_in_batched_module())
    seen: list = []
    scores = {256: 0.3, 512: KeyboardInterrupt(), 768: RuntimeError("no feasible world"), 1024: 0.1}
    monkeypatch.setattr(selection, "validate", _scripted(scores, seen))
    out = tmp_path / "run"
    with pytest.raises(KeyboardInterrupt):
        train(_small(timesteps=1024), out)
    assert read_bundle_meta(out / "checkpoint.zip")[0]["state"]["validated_at"] == 256
    scores[516] = 0.6
    train(_small(timesteps=1024), out, resume=True)
    # made again after the resumed part's first step (4 worlds); 768 failed and the run went on
    assert [s[0] for s in seen] == [256, 512, 516, 768, 1024]
    rows = selection.read_validation(out)
    assert [r["timesteps"] for r in rows] == [256, 516, 1024]
    assert read_bundle_meta(out / selection.BEST)[0]["timesteps"] == 516

    train(_small(timesteps=1100), out, resume=True, resume_overrides={"validate_every": 0})
    assert len(seen) == 5  # "never" holds for the last checkpoint too
    with pytest.raises(CheckpointError, match="best.zip is left from an earlier run"):
        (out / "checkpoint.zip").unlink()
        train(_small(timesteps=1100), out)


def test_validation_leaves_the_runs_random_generators_and_threads_alone(monkeypatch):
    import random

    import numpy as np
    import torch

    torch.set_num_threads(2)
    random.seed(5), np.random.seed(5), torch.manual_seed(5)
    expected = random.random(), np.random.rand(), torch.rand(1).item()
    random.seed(5), np.random.seed(5), torch.manual_seed(5)
    row = selection.validate(SHIPPED_UR5, "ur5", "random", 2)  # loads the policy: SB3 reseeds and sets 1 thread
    assert (random.random(), np.random.rand(), torch.rand(1).item()) == expected
    assert torch.get_num_threads() == 2
    assert row["worlds"] == 2 and row["obstacles"] == 2
    assert sum(row[f"{o}_rate"] for o in ("success", "collision", "out_of_bounds", "timeout")) == pytest.approx(1)
    assert row["score"] == pytest.approx(row["success_rate"] - row["collision_rate"])


def test_a_run_shorter_than_one_interval_chooses_nothing(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "rayreach.env.batched", _stand_in_batched_module())
    seen: list = []
    monkeypatch.setattr(selection, "validate", _scripted({}, seen))
    train(_small(timesteps=512, validate_every=10**6), tmp_path / "run")
    assert seen == [] and not (tmp_path / "run" / selection.BEST).exists()
    assert run_bundle(tmp_path / "run") == tmp_path / "run" / "model.zip"


def test_validation_plays_the_checkpoint_alone_on_the_robots_task(monkeypatch):
    from rayreach.evaluate import rollout

    calls = []
    real = rollout.rollout_batched
    monkeypatch.setattr(rollout, "rollout_batched", lambda model, **kw: calls.append(kw) or real(model, **kw))
    selection.validate(SHIPPED_UR5, "ur5", "broad", 1)
    assert calls == [{"episodes": 1, "goal_tolerance": 0.01, "n_obstacles": selection.BROAD_ELEMENTS,
                      "seed": selection.SELECTION_SEED, "split": "validation", "suite": "broad"}]
    assert (selection.task_obstacles("ur5", "random"), selection.task_obstacles("kr16", "random")) == (2, 1)


def test_validation_settings_are_checked_and_exported():
    with pytest.raises(ValueError, match="validate_every must be >= 0"):
        TrainConfig(validate_every=-1)
    assert recipe("paper").validate_every == recipe("baseline").validate_every == 0
    chosen = asdict(recipe("default", robot="ur5", validate_every=10**6, validate_worlds=200))
    assert "--validate-every 1000000 --validate-worlds 200 [--resume]" in train_command(chosen, "runs/x")
    assert "--validate" not in train_command(asdict(recipe("default")), "runs/x")
    assert "--validate-every 0 [--resume]" in train_command(asdict(recipe("default", validate_every=0)), "runs/x")
    assert "--validate" not in train_command(asdict(recipe("paper")), "runs/x")
