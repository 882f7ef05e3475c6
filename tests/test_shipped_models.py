"""The policies in models/ load with their frozen normalisation and drive the executor."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from rayreach.execution import Executor
from rayreach.planners import make_planner
from rayreach.planners.drl import MODELS_DIR

CASES = [("ur5", "exp1"), ("kr16", "exp4")]


@pytest.mark.parametrize("robot,scenario", CASES)
def test_shipped_policy_loads_with_metadata_and_runs_an_episode(robot, scenario):
    bundle = MODELS_DIR / f"{robot}.zip"
    meta = json.loads(Path(bundle.with_suffix(".json")).read_text())
    assert meta["robot"] == robot and meta["timesteps"] > 0 and "rayreach train" in meta["command"]
    planner = make_planner("drl", robot)
    assert planner.policy.normalization is not None  # training's statistics travel with the policy
    with Executor(scenario) as ex:
        record = ex.run(planner, seed=0)
    assert record.outcome in {"success", "collision", "timeout", "out of bounds"}
    assert 0 < record.steps <= 1024 and record.config["timesteps"] == meta["timesteps"]
    assert np.isfinite(record.ee_path).all()


def test_a_drl_model_for_the_other_robot_is_refused():
    with pytest.raises(ValueError, match="is a ur5 policy, not kr16"):
        make_planner("drl", "kr16", model=MODELS_DIR / "ur5.zip")
