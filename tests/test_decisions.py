"""A policy that decides every k control steps: the training wrapper and the acting policy
hold an action for k steps, and nothing else changes."""

from __future__ import annotations

from dataclasses import asdict

import numpy as np
import pytest

from rayreach.acting import ActingPolicy
from rayreach.acting.resample import HELD_DRAW_STD
from rayreach.env.batched import BatchedReachEnv
from rayreach.env.decisions import DecisionPeriod, HeldAction, check_period
from rayreach.env.reach import ReachEnv
from rayreach.learning.train import RECIPES, TrainConfig, config_from_meta, recipe

SEED = 300


def _actions(rng: np.random.Generator, n: int) -> np.ndarray:
    return rng.uniform(-1, 1, (n, 6)).astype(np.float32)


def test_a_decision_is_k_control_steps_with_the_action_held():
    """Against the unwrapped worlds stepped k times by hand: the same observations, summed
    rewards and episode ends, and a world that ended stands still until the next decision."""
    k, n = 4, 6
    wrapped = DecisionPeriod(BatchedReachEnv("ur5", n, seed=SEED), k)
    plain = BatchedReachEnv("ur5", n, seed=SEED)
    rng = np.random.default_rng(1)
    ends = 0
    try:
        np.testing.assert_array_equal(wrapped.reset(), plain.reset())
        for _ in range(60):
            actions = _actions(rng, n)
            obs, rewards, dones, infos = wrapped.step(actions)
            expected_rewards = np.zeros(n)
            ended = np.zeros(n, dtype=bool)
            first_infos: list[dict] = [{} for _ in range(n)]
            for _ in range(k):
                o, r, d, i = plain.step(np.where(ended[:, None], 0.0, actions))
                expected_rewards += np.where(ended, 0.0, r)
                for w in np.flatnonzero(d & ~ended):
                    first_infos[w] = i[w]
                ended |= d
                if ended.all():
                    break
            np.testing.assert_allclose(obs, o, atol=0)
            np.testing.assert_allclose(rewards, expected_rewards, rtol=1e-6, atol=1e-6)
            np.testing.assert_array_equal(dones, ended)
            for w in np.flatnonzero(dones):
                assert infos[w]["is_success"] == first_infos[w]["is_success"]
                np.testing.assert_array_equal(infos[w]["terminal_observation"], first_infos[w]["terminal_observation"])
            ends += int(dones.sum())
        assert ends >= 4  # the comparison saw episodes end inside a decision
    finally:
        wrapped.close()
        plain.close()


def test_a_world_that_ended_starts_its_next_episode_standing_still():
    """Within a decision, a world whose episode ended is not turned by the old action: its
    tool still has the orientation it started the new episode with."""
    wrapped = DecisionPeriod(BatchedReachEnv("ur5", 4, seed=SEED), 8)
    try:
        wrapped.reset()
        rng = np.random.default_rng(2)
        seen = 0
        for _ in range(100):
            obs, _, dones, _ = wrapped.step(_actions(rng, 4))
            for w in np.flatnonzero(dones):
                assert wrapped.venv.steps[w] < 8
                np.testing.assert_allclose(obs[w, 9:12], 0.0, atol=1e-9)  # roll, pitch, yaw since the start
                seen += 1
        assert seen >= 3
    finally:
        wrapped.close()


def test_period_one_is_the_env_itself():
    wrapped = DecisionPeriod(BatchedReachEnv("ur5", 3, seed=SEED), 1)
    plain = BatchedReachEnv("ur5", 3, seed=SEED)
    rng = np.random.default_rng(3)
    try:
        np.testing.assert_array_equal(wrapped.reset(), plain.reset())
        for _ in range(20):
            a = _actions(rng, 3)
            o1, r1, d1, _ = wrapped.step(a)
            o2, r2, d2, _ = plain.step(a)
            np.testing.assert_array_equal(o1, o2)
            np.testing.assert_allclose(r1, r2, rtol=1e-6)
            np.testing.assert_array_equal(d1, d2)
    finally:
        wrapped.close()
        plain.close()


@pytest.mark.parametrize("bad", [0, -2, 1.5])
def test_bad_periods_are_refused(bad):
    with pytest.raises(ValueError, match="decision_period must be a whole number of control steps >= 1"):
        check_period(bad)


def test_one_world_decides_the_same_way():
    """``HeldAction`` over a ``ReachEnv`` is k steps of that env with the action held, ended
    where its episode ends."""
    k = 3
    held = HeldAction(ReachEnv(robot="ur5"), k)
    plain = ReachEnv(robot="ur5")
    rng = np.random.default_rng(4)
    try:
        obs, _ = held.reset(seed=SEED)
        np.testing.assert_array_equal(obs, plain.reset(seed=SEED)[0])
        for _ in range(200):
            a = _actions(rng, 1)[0]
            obs, reward, terminated, truncated, _ = held.step(a)
            total, n = 0.0, 0
            while n < k:
                o, r, t, u, _ = plain.step(a)
                total, n = total + r, n + 1
                if t or u:
                    break
            np.testing.assert_array_equal(obs, o)
            assert reward == pytest.approx(total) and (terminated, truncated) == (t, u)
            if terminated or truncated:
                break
        else:
            pytest.fail("no episode ended in 200 decisions of random actions")
    finally:
        held.close()
        plain.close()


def test_the_recipes_periods():
    """The default decides every 4 control steps; the paper's and the baseline's agents every
    step, and so does a run saved before the choice."""
    assert recipe("default", robot="kr16").decision_period == 4
    assert RECIPES["paper"].decision_period == RECIPES["baseline"].decision_period == 1
    saved = {"config": {k: v for k, v in asdict(TrainConfig()).items() if k != "decision_period"}}
    assert config_from_meta(saved).decision_period == 1


class _CountingPolicy:
    """A stand-in policy: each call's action is the call's number."""

    def __init__(self, period: int) -> None:
        self.decision_period = period
        self.calls = 0

    def act(self, obs, deterministic=True):
        self.calls += 1
        return np.full(6, float(self.calls), dtype=np.float32)

    def sample(self, obs, rng, least_std=0.0):
        self.calls += 1
        self.least_std = least_std
        return np.full(6, -float(self.calls), dtype=np.float32)


def test_the_acting_policy_holds_each_action_for_the_period():
    policy = _CountingPolicy(3)
    actor = ActingPolicy(policy)  # type: ignore[arg-type]
    actor.reset(0)
    firsts = [actor.act(np.zeros(4), {})[0] for _ in range(7)]
    assert firsts == [1, 1, 1, 2, 2, 2, 3]
    actor.reset(0)  # a new episode decides on its first step
    assert actor.act(np.zeros(4), {})[0] == 4
    # a held arm draws a new action at once, and holds that one
    assert actor.act(np.zeros(4), {"acting": {"held": True}})[0] == -5
    assert policy.least_std == HELD_DRAW_STD  # drawn at least that wide
    assert actor.act(np.zeros(4), {})[0] == -5


def test_a_policy_of_period_one_decides_every_step():
    policy = _CountingPolicy(1)
    actor = ActingPolicy(policy)  # type: ignore[arg-type]
    actor.reset(0)
    assert [actor.act(np.zeros(4), {})[0] for _ in range(4)] == [1, 2, 3, 4]


def test_the_learning_curve_counts_decisions_where_a_decision_is_several_steps(tmp_path):
    import matplotlib.image

    from rayreach.learning.train import plot_curve, steps_label

    assert steps_label(1) == "environment steps"
    assert steps_label(4) == "decisions (each 4 control steps)"
    header = "timesteps,goal_size,obstacles,success_rate,collision_rate,out_of_bounds_rate,timeout_rate\n"
    (tmp_path / "curve.csv").write_text(header + "16384,0.1,1,0.5,0.2,0.1,0.2\n32768,0.09,1,0.6,0.2,0.1,0.1\n")
    png = plot_curve(tmp_path / "curve.csv", tmp_path / "curve.png", "UR5", decision_period=4)
    assert matplotlib.image.imread(png).shape[:2] == (660, 880)
