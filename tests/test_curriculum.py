"""The augmented goal size against each branch of the paper's equation, and the obstacle rule."""

from __future__ import annotations

import pytest

from rayreach.learning.curriculum import (
    AugmentedGoalSize,
    GoalSizeParams,
    ObstacleCurriculum,
    ObstacleParams,
    next_goal_size,
)

P = GoalSizeParams()  # the paper's table: 0.1, 0.01, 0.001, 0.01, 1e3, 0.9, 50


def test_paper_parameters():
    assert (P.rho_max, P.rho_min, P.delta_plus, P.delta_minus, P.e_zeta, P.p_zeta, P.k) == (
        0.1, 0.01, 0.001, 0.01, 1000, 0.9, 50
    )


def test_branch_before_e_zeta_keeps_rho():
    assert next_goal_size(0.05, episode=999, eta=0.0, p=P) == P.rho
    assert next_goal_size(0.05, episode=999, eta=1.0, p=P) == P.rho


def test_branch_failing_grows_by_delta_plus_below_max():
    assert next_goal_size(0.05, episode=1000, eta=0.5, p=P) == pytest.approx(0.051)
    assert next_goal_size(0.0995, episode=5000, eta=0.0, p=P) == pytest.approx(0.1)  # capped at rho_max


def test_branch_succeeding_shrinks_by_delta_minus_above_min():
    assert next_goal_size(0.05, episode=1000, eta=0.9, p=P) == pytest.approx(0.04)
    assert next_goal_size(0.015, episode=1000, eta=0.95, p=P) == pytest.approx(0.01)  # floored at rho_min


def test_branch_perfect_at_rho_stays_rho():
    p = GoalSizeParams(rho=0.01)  # rho equal to rho_min: neither shrink nor grow applies
    assert next_goal_size(0.01, episode=2000, eta=1.0, p=p) == 0.01


def test_branch_otherwise_unchanged():
    assert next_goal_size(P.rho_max, episode=2000, eta=0.2, p=P) == P.rho_max  # failing at the maximum
    assert next_goal_size(P.rho_min, episode=2000, eta=0.95, p=P) == P.rho_min  # succeeding at the minimum


def test_eta_is_successes_in_last_k_over_k():
    goal = AugmentedGoalSize(GoalSizeParams(k=4, e_zeta=0))
    for s in (True, True, False, True, True):
        goal.record(s)
    assert list(goal.window) == [1, 0, 1, 1]
    assert goal.eta() == pytest.approx(0.75)


def test_one_state_for_all_envs_and_round_trip():
    goal = AugmentedGoalSize(GoalSizeParams(e_zeta=3, k=3))
    sizes = [goal.record(True) for _ in range(5)]
    assert sizes[:2] == [0.1, 0.1] and sizes[2] == pytest.approx(0.09) and sizes[4] == pytest.approx(0.07)
    again = AugmentedGoalSize.from_state(goal.state())
    assert again.state() == goal.state()
    assert again.record(False) == goal.record(False)


def test_obstacle_curriculum_rises_on_true_size_episodes_and_falls_on_all():
    c = ObstacleCurriculum(ObstacleParams(start=0, window=10, raise_at=0.8, lower_at=0.3, maximum=2))
    for _ in range(30):
        c.record(True, at_true_size=False)  # success with an enlarged goal says nothing
    assert c.count == 0
    for _ in range(10):
        c.record(True)
    assert c.count == 1
    for _ in range(8):
        c.record(True)
    for _ in range(2):
        c.record(False)
    assert c.count == 2  # 80 % at the true size is enough
    for _ in range(10):
        c.record(True)
    assert c.count == 2  # capped at the maximum
    for _ in range(10):
        c.record(False, at_true_size=False)
    assert c.count == 1  # any 10 episodes below 30 % lower it
    assert ObstacleCurriculum.from_state(c.state()).state() == c.state()


def test_a_mixed_count_spreads_the_worlds_evenly_over_one_to_the_count():
    mixed = ObstacleParams(start=3, minimum=3, maximum=3, mix=True)
    assert mixed.world_counts(3, 7) == [1, 2, 3, 1, 2, 3, 1]
    assert mixed.world_counts(1, 3) == [1, 1, 1]
    assert mixed.world_counts(0, 2) == [0, 0]
    assert ObstacleParams().world_counts(2, 3) == [2, 2, 2]
