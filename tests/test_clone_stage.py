"""The demonstration stage that ``rayreach train`` runs itself (``rayreach.learning.clone_stage``)."""

import json
from dataclasses import replace

import pytest

from rayreach.learning import clone_stage
from rayreach.learning.bundles import CheckpointError, read_bundle_meta
from rayreach.learning.demonstrations import CloneConfig, clone_into_checkpoint
from rayreach.learning.train import CHECKPOINT, TrainConfig, config_from_meta, recipe, with_envs

TINY_CLONE = CloneConfig(episodes=1, rounds=1, anchor_episodes=1, eval_episodes=1)


def tiny_broad(**changes) -> TrainConfig:
    """256 decisions, then the two broad experts, then 256 more (64 decisions a rollout)."""
    settings = dict(workers=1, max_episode_steps=32, timesteps=512, suite="broad", checkpoint_every=64,
                    validate_every=0, clone_at=256, clone_kinds=("goal_box", "shelf"))
    return replace(with_envs(TrainConfig(n_steps=16), 4), **{**settings, **changes})


def test_the_default_recipe_clones_the_box_and_shelf_experts_in_broad_worlds_only():
    broad = recipe("default", robot="ur5", suite="broad")
    assert broad.clone_kinds == ("goal_box", "shelf") and 0 < broad.clone_at < broad.timesteps
    kr16 = recipe("default", robot="kr16", suite="broad")
    assert kr16.starts == 1 and not kr16.observation.tip_back  # one start; the robot's other defaults stay
    assert broad.obstacles.mix and broad.obstacles.world_counts(3, 4) == [1, 2, 3, 1]  # one to three elements
    assert not recipe("default", robot="ur5").obstacles.mix
    for config in (recipe("default", robot="ur5"), recipe("paper", robot="ur5", suite="broad")):
        assert config.clone_kinds == () and config.clone_at == 0


def test_clone_settings_are_checked_and_name_what_is_valid():
    with pytest.raises(ValueError, match="clone_kinds can name: shelf, goal_box"):
        TrainConfig(suite="broad", clone_at=10, clone_kinds=("goal_slot",))
    with pytest.raises(ValueError, match="clone_at must be > 0 with clone_kinds and 0 without"):
        TrainConfig(suite="broad", clone_kinds=("shelf",))
    with pytest.raises(ValueError, match="clone_at must be > 0 with clone_kinds and 0 without"):
        TrainConfig(clone_at=10)
    with pytest.raises(ValueError, match="give start_decisions below clone_at, or one start"):
        TrainConfig(suite="broad", clone_at=10, clone_kinds=("shelf",), starts=2, start_decisions=10)


def test_a_run_stopped_inside_the_critic_warmup_finishes_it_and_a_new_run_refuses_old_clones(tmp_path):
    warmup = clone_stage.CLONE_CRITIC_WARMUP
    assert clone_stage.warmup_left(1000, 1000) == warmup
    assert clone_stage.warmup_left(1000 + warmup // 2, 1000) == warmup - warmup // 2
    assert clone_stage.warmup_left(1000 + warmup, 1000) == 0
    (tmp_path / "clone-shelf.json").write_text("{}")
    with pytest.raises(CheckpointError, match="clone-shelf.json in .* left from an earlier run: pass --resume"):
        clone_stage.train_with_clone(tiny_broad(), tmp_path)


def test_a_run_clones_each_expert_at_its_decision_and_resumes_after_a_stop_in_the_stage(tmp_path, monkeypatch):
    """The run trains to ``clone_at``, clones the box expert, then stops in the shelf's clone;
    resumed, it clones the shelf only, fits the critic alone first, and trains to the end."""
    out = tmp_path / "run"
    calls: list[tuple[str, int]] = []

    def clone_then_stop_at_shelf(run, kind, config, progress):
        calls.append((kind, int(read_bundle_meta(run / CHECKPOINT)[0]["timesteps"])))
        if kind == "shelf":
            raise KeyboardInterrupt
        return clone_into_checkpoint(run, kind, config, progress)

    monkeypatch.setattr(clone_stage, "clone_into_checkpoint", clone_then_stop_at_shelf)
    with pytest.raises(KeyboardInterrupt):
        clone_stage.train_with_clone(tiny_broad(), out, clone=TINY_CLONE, progress=False)
    assert calls == [("goal_box", 256), ("shelf", 256)]
    assert json.loads((out / "clone-goal_box.json").read_text())["timesteps"] == 256
    assert not (out / "clone-shelf.json").exists()
    assert (out / "demos-goal_box.npz").exists()  # for an imitation term later

    calls.clear()
    monkeypatch.setattr(clone_stage, "clone_into_checkpoint",
                        lambda *a: calls.append((a[1], 0)) or clone_into_checkpoint(*a))
    warmups = []
    real_train = clone_stage.train
    monkeypatch.setattr(clone_stage, "train", lambda *a, **k: warmups.append(k["critic_warmup"]) or real_train(*a, **k))
    # the resumed command's config need not say how the run clones: its checkpoint does
    model = clone_stage.train_with_clone(tiny_broad(clone_at=0, clone_kinds=()), out, resume=True, clone=TINY_CLONE,
                                         progress=False)
    assert calls == [("shelf", 0)] and warmups == [clone_stage.CLONE_CRITIC_WARMUP]
    meta = read_bundle_meta(model)[0]
    assert meta["timesteps"] == 512
    assert config_from_meta(meta).clone_kinds == ("goal_box", "shelf")


def test_a_clone_stopped_after_its_checkpoint_is_not_made_again(tmp_path, monkeypatch):
    """The cloned actor and its report are saved in one write: a stop before the report's own
    file loses neither, and the resumed run writes the file and trains on without a second clone."""
    from rayreach.learning import demonstrations

    out = tmp_path / "run"

    def stop(run, report):
        raise KeyboardInterrupt

    monkeypatch.setattr(demonstrations, "write_report", stop)
    config = tiny_broad(clone_kinds=("goal_box",), timesteps=384)
    with pytest.raises(KeyboardInterrupt):
        clone_stage.train_with_clone(config, out, clone=TINY_CLONE, progress=False)
    assert not (out / "clone-goal_box.json").exists()
    held = read_bundle_meta(out / CHECKPOINT)[0]["state"]["clones"]["goal_box"]
    assert held["kind"] == "goal_box" and held["timesteps"] == 256
    monkeypatch.undo()
    monkeypatch.setattr(clone_stage, "clone_into_checkpoint", lambda *a: pytest.fail("cloned a second time"))
    model = clone_stage.train_with_clone(config, out, resume=True, clone=TINY_CLONE, progress=False)
    assert json.loads((out / "clone-goal_box.json").read_text()) == held
    assert read_bundle_meta(model)[0]["timesteps"] == 384


def test_part_settings_wait_for_the_clone_and_a_run_that_ends_before_it_does_not_clone(tmp_path, monkeypatch):
    with pytest.raises(ValueError, match="critic_warmup apply to one part of a run.*goal_box, shelf"):
        clone_stage.train_with_clone(tiny_broad(), tmp_path / "a", critic_warmup=10)
    monkeypatch.setattr(clone_stage, "clone_into_checkpoint", lambda *a: pytest.fail("cloned before clone_at"))
    model = clone_stage.train_with_clone(tiny_broad(timesteps=128), tmp_path / "b", progress=False)
    assert read_bundle_meta(model)[0]["timesteps"] == 128
