"""The paper's environment stands alone; every acting layer has one switch, by name."""

from __future__ import annotations

import subprocess
import sys

import pytest

from exp1_scenes import SLIDING_STACK
from rayreach.acting import LAYERS, ActingConfig
from rayreach.acting.shield import SLIDE
from rayreach.cli import acting_from_args, build_parser
from rayreach.planners import DRL_PLANNERS, drl_acting


def test_the_papers_environment_imports_no_acting_module():
    """Made and stepped through Gymnasium, in a fresh interpreter (this one has imported the
    acting layers already)."""
    code = """
import sys, gymnasium as gym, rayreach
for robot in ("UR5", "KR16"):
    env = gym.make(f"rayreach/Reach-{robot}-v0"); env.reset(seed=0)
    for _ in range(20):
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        if terminated or truncated:
            env.reset()
    env.close()
print(sorted(m for m in sys.modules if m.startswith("rayreach.acting")))
"""
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip().splitlines()[-1] == "[]"


SHIPPED = tuple(name for name in LAYERS if name != "slide")
"""The shipped stack: every layer but the slide, which earned its place with neither policy."""


def test_each_layer_switches_off_by_name_and_only_that_layer():
    assert ActingConfig().layers == SHIPPED
    assert SLIDING_STACK.layers == LAYERS  # the slide, asked for, is a layer like the others
    for layer in LAYERS:
        assert SLIDING_STACK.without(layer).layers == tuple(name for name in LAYERS if name != layer)
        assert ActingConfig().without(layer).layers == tuple(name for name in SHIPPED if name != layer)
    assert ActingConfig.off().layers == () and SLIDING_STACK.without(*LAYERS).layers == ()
    assert ActingConfig.training().layers == ("ray_shield", "workspace_guard", "arm_guard")
    with pytest.raises(ValueError, match=r"unknown acting layer\(s\) \['shield'\]; known: final_approach, ray_shield"):
        ActingConfig().without("shield")


def test_the_rollout_command_has_one_switch_per_layer():
    parser = build_parser()
    base = ["rollout", "--model", "m.zip", "exp1"]
    assert acting_from_args(parser.parse_args(base)).layers == SHIPPED
    assert acting_from_args(parser.parse_args([*base, "--slide", str(SLIDE)])).layers == LAYERS
    for layer in LAYERS:
        flag = f"--no-{layer.replace('_', '-')}"
        assert acting_from_args(parser.parse_args([*base, flag])) == ActingConfig().without(layer)
    assert acting_from_args(parser.parse_args([*base, "--policy-alone"])) == ActingConfig.off()
    tuned = acting_from_args(parser.parse_args([*base, "--ray-shield", "0.08", "--no-slide"]))
    assert tuned.safety.ray_shield == 0.08 and "slide" not in tuned.layers
    assert acting_from_args(parser.parse_args([*base, "--held-draw-std", "0"])).held_draw_std == 0.0


def test_drl_planner_names_are_the_stack_the_policy_alone_and_the_stack_minus_one_layer():
    assert drl_acting("drl") == ActingConfig() and drl_acting("drl-alone") == ActingConfig.off()
    for layer in SHIPPED:
        assert f"drl-no-{layer}" in DRL_PLANNERS and drl_acting(f"drl-no-{layer}") == ActingConfig().without(layer)
    assert "drl-no-slide" not in DRL_PLANNERS  # the same stack as drl: the slide is off in it
    with pytest.raises(ValueError, match="unknown DRL planner 'drl-no-wings'; valid: drl, drl-alone"):
        drl_acting("drl-no-wings")


def test_bench_acting_times_every_variant_on_the_same_worlds(monkeypatch):
    from rayreach.evaluate import bench_acting as bench
    from rayreach.planners.drl import MODELS_DIR

    monkeypatch.setattr(bench, "VARIANTS", {"drl": ActingConfig(), "drl-alone": ActingConfig.off()})
    record = bench.bench_acting(MODELS_DIR / "ur5.zip", episodes=1, progress=False)
    assert set(record) == {"drl", "drl-alone"} and record["drl"]["ratio"] == 1.0
    assert all(r["steps"] > 0 and r["us_per_step"] > 0 for r in record.values())


def test_an_acting_env_refuses_wrappers_it_would_step_past_and_a_reset_it_did_not_make():
    import gymnasium as gym
    import numpy as np
    from gymnasium.wrappers import RecordEpisodeStatistics

    from rayreach.acting import ActingEnv

    with pytest.raises(TypeError, match="would pass RecordEpisodeStatistics by; wrap the ActingEnv in it instead"):
        ActingEnv(RecordEpisodeStatistics(gym.make("rayreach/Reach-UR5-v0", scenario="exp1")))
    first = ActingEnv(gym.make("rayreach/Reach-UR5-v0", scenario="exp1"))  # the checkers gym.make adds may stay
    try:
        first.reset(seed=0)
        first.step(np.zeros(6))
        ActingEnv(first.env, ActingConfig.off()).reset(seed=0)
        with pytest.raises(RuntimeError, match="another wrapper has reset the environment since this one did"):
            first.step(np.zeros(6))
    finally:
        first.close()
