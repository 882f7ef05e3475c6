"""Reward terms against the paper's equations and the shaking algorithm
("Number of uneven movements in past 10 steps")."""

from __future__ import annotations

from collections import deque

import numpy as np
import pytest

from rayreach.env import rewards as R


def test_default_weights_are_the_papers():
    w = R.RewardWeights()
    assert (w.success, w.collision, w.distance, w.out_of_bounds, w.exhausted, w.shaking) == (
        10.0,
        -10.0,
        -0.01,
        -10.0,
        -5.0,
        -0.005,
    )


@pytest.mark.parametrize(
    "distance, tolerance, expected",
    [
        (0.0, 0.01, 10.0),
        (0.0099, 0.01, 10.0),
        (0.01, 0.01, 0.0),
        (0.0101, 0.01, 0.0),
        (0.5, 0.01, 0.0),
        (0.29, 0.3, 10.0),
        (0.3, 0.3, 0.0),
    ],
)
def test_success_reward_strictly_below_threshold(distance, tolerance, expected):
    # r_suc = 10 if d_t < d_Th else 0
    assert R.success_reward(distance, tolerance) == expected


def test_collision_reward():
    assert R.collision_reward(True) == -10.0
    assert R.collision_reward(False) == 0.0


@pytest.mark.parametrize("d", [0.0, 0.001, 0.25, 1.0, 3.7])
def test_distance_reward_is_linear(d):
    assert R.distance_reward(d) == pytest.approx(-0.01 * d, abs=1e-15)


def test_out_of_bounds_and_exhausted_rewards():
    assert R.out_of_bounds_reward(True) == -10.0
    assert R.out_of_bounds_reward(False) == 0.0
    assert R.exhausted_reward(True) == -5.0
    assert R.exhausted_reward(False) == 0.0


@pytest.mark.parametrize("n", [0, 1, 4, 9])
def test_shaking_reward(n):
    assert R.shaking_reward(n) == pytest.approx(-0.005 * n, abs=1e-15)


def test_custom_weights_are_used():
    w = R.RewardWeights(
        success=1.0, collision=-2.0, distance=-3.0, out_of_bounds=-4.0, exhausted=-6.0, shaking=-7.0
    )
    assert R.success_reward(0.0, 0.1, w) == 1.0
    assert R.collision_reward(True, w) == -2.0
    assert R.distance_reward(2.0, w) == -6.0
    assert R.out_of_bounds_reward(True, w) == -4.0
    assert R.exhausted_reward(True, w) == -6.0
    assert R.shaking_reward(3, w) == -21.0


def test_shielded_reward_is_the_removed_share_of_the_commanded_translation():
    step = np.array([0.005, 0.0, 0.0])
    assert R.shielded_reward(step, np.zeros(3)) == 0.0  # off in the paper's reward
    w = R.RewardWeights(shielded=-0.1)
    assert R.shielded_reward(step, np.zeros(3), w) == pytest.approx(-0.1)
    assert R.shielded_reward(step, step / 2, w) == pytest.approx(-0.05)
    assert R.shielded_reward(step, step, w) == 0.0
    slid = R.shielded_reward(np.array([0.003, 0.004, 0.0]), np.array([0.003, 0.0, 0.0]), w)
    assert slid == pytest.approx(-0.1 * 0.8)  # 4 of the step's 5 mm removed
    assert R.shielded_reward(np.zeros(3), np.zeros(3), w) == 0.0


# ---------------------------------------------------------------------- the paper's algorithm
def paper_n_s(queue: list[float]) -> int:
    """The paper's loops written out literally: L_m gets 0 when Q_d[i+1] - Q_d[i] >= 0, else 1;
    n_s counts j with L_m[j] != L_m[j+1]."""
    lm = []
    for i in range(len(queue) - 1):
        lm.append(0 if queue[i + 1] - queue[i] >= 0 else 1)
    n_s = 0
    for j in range(len(lm) - 1):
        if lm[j] != lm[j + 1]:
            n_s += 1
    return n_s


@pytest.mark.parametrize(
    "distances, expected",
    [
        ([], 0),
        ([0.5], 0),
        ([0.5, 0.4], 0),
        ([0.5, 0.4, 0.3, 0.2, 0.1], 0),  # steadily approaching
        ([0.1, 0.2, 0.3, 0.4], 0),  # steadily receding
        ([0.3, 0.3, 0.3, 0.3], 0),  # standing still: all labels 0
        ([0.5, 0.4, 0.5], 1),  # down, up
        ([0.5, 0.4, 0.5, 0.4], 2),  # down, up, down
        ([0.5, 0.4, 0.5, 0.4, 0.5, 0.4, 0.5, 0.4, 0.5, 0.4, 0.5], 9),  # alternating: every pair changes
        ([0.5, 0.4, 0.4], 1),  # decrease (1) then equal (0): a change
        ([0.4, 0.4, 0.3], 1),  # equal (0) then decrease (1)
        ([0.4, 0.4, 0.5], 0),  # equal (0) then increase (0): no change
        ([0.5, 0.4, 0.3, 0.35, 0.36, 0.2], 2),  # 1 1 0 0 1
    ],
)
def test_count_uneven_movements(distances, expected):
    assert R.count_uneven_movements(distances) == expected
    assert paper_n_s(distances) == expected
    assert R.count_uneven_movements(deque(distances)) == expected


def test_count_uneven_movements_matches_literal_algorithm_on_random_sequences():
    import numpy as np

    rng = np.random.default_rng(0)
    for _ in range(500):
        n = int(rng.integers(0, 14))
        seq = list(np.round(rng.uniform(0, 1, n), 1))  # rounding makes ties common
        assert R.count_uneven_movements(seq) == paper_n_s(seq)


def test_shake_counter_keeps_at_most_eleven_distances():
    """Pop when len(Q_d) > 10, *then* append: the queue holds at most 11 distances."""
    counter = R.ShakeCounter()
    lengths = []
    for t in range(30):
        counter.update(float(t))
        lengths.append(len(counter.queue))
    assert lengths[:11] == list(range(1, 12))
    assert set(lengths[11:]) == {11}
    assert list(counter.queue) == [float(t) for t in range(19, 30)]


def test_shake_counter_matches_the_paper_step_by_step():
    import numpy as np

    rng = np.random.default_rng(1)
    counter = R.ShakeCounter()
    reference: deque[float] = deque()
    for _ in range(200):
        d = float(np.round(rng.uniform(0, 1), 1))
        if len(reference) > 10:
            reference.popleft()
        reference.append(d)
        assert counter.update(d) == paper_n_s(list(reference))
        assert list(counter.queue) == list(reference)


def test_shake_counter_alternating_saturates_at_nine():
    """11 distances give 10 labels and at most 9 label changes."""
    counter = R.ShakeCounter()
    values = [counter.update(0.5 if t % 2 else 0.4) for t in range(25)]
    assert values[:3] == [0, 0, 1]
    assert max(values) == 9 and values[-1] == 9


def test_shake_counter_forgets_old_shaking():
    counter = R.ShakeCounter()
    for t in range(6):
        counter.update(0.5 if t % 2 else 0.4)
    assert counter.update(0.3) > 0
    n = None
    for k in range(11):  # steadily approaching pushes the shaking out of the window
        n = counter.update(0.29 - 0.01 * k)
    assert n == 0


def test_shake_counter_reset():
    counter = R.ShakeCounter()
    for d in (0.5, 0.4, 0.5):
        counter.update(d)
    counter.reset()
    assert len(counter.queue) == 0
    assert counter.update(0.4) == 0


def test_progress_term_is_off_by_default_and_rewards_getting_closer():
    from rayreach.env.rewards import RewardWeights, progress_reward

    assert progress_reward(0.30, 0.25) == 0.0
    w = RewardWeights(progress=10.0)
    assert progress_reward(0.30, 0.25, w) == pytest.approx(0.5)
    assert progress_reward(0.25, 0.30, w) == pytest.approx(-0.5)


def test_proximity_term_is_off_by_default_and_grows_towards_contact():
    from rayreach.env.rewards import RewardWeights, proximity_reward

    assert proximity_reward(0.0) == 0.0
    w = RewardWeights(proximity=-0.1, proximity_range=0.25)
    assert proximity_reward(1.0, w) == 0.0 and proximity_reward(0.25, w) == 0.0
    assert proximity_reward(0.125, w) == pytest.approx(-0.05)
    assert proximity_reward(0.0, w) == pytest.approx(-0.1)
