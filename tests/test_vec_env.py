"""WorkerVecEnv steps exactly like SB3's DummyVecEnv and reaches each env by index."""

from __future__ import annotations

import time

import numpy as np
from stable_baselines3.common.vec_env import DummyVecEnv

from rayreach.learning.train import TrainConfig, make_env_fn
from rayreach.learning.vec_env import WorkerVecEnv


def test_worker_vec_env_matches_dummy_vec_env_and_routes_attributes():
    config = TrainConfig(envs=3)
    fns = [make_env_fn(config, i) for i in range(3)]
    workers, dummy = WorkerVecEnv(fns, n_workers=2), DummyVecEnv(fns)
    try:
        for venv in (workers, dummy):
            venv.seed(5)
        obs_w, obs_d = workers.reset(), dummy.reset()
        np.testing.assert_array_equal(obs_w, obs_d)
        rng = np.random.default_rng(0)
        dones_seen = 0
        for _ in range(150):
            actions = (rng.uniform(-1, 1, (3, 6)) + [0, 0, 0.8, 0, 0, 0]).astype(np.float32)  # drift up and out
            ow, rw, dw, iw = workers.step(actions)
            od, rd, dd, idd = dummy.step(actions)
            np.testing.assert_array_equal(ow, od)
            np.testing.assert_array_equal(rw, rd)
            np.testing.assert_array_equal(dw, dd)
            for a, b in zip(iw, idd):
                if "terminal_observation" in b:
                    np.testing.assert_array_equal(a["terminal_observation"], b["terminal_observation"])
            dones_seen += int(dw.sum())
        assert dones_seen > 0  # auto-reset was exercised
        workers.set_attr("n_obstacles", 2, indices=[0, 2])
        assert workers.get_attr("n_obstacles") == [2, 1, 2]
        workers.env_method("set_goal_tolerance", 0.05, indices=[1])
        assert [c.goal_tolerance for c in workers.get_attr("config")] == [0.1, 0.05, 0.1]
        assert workers.env_is_wrapped(type(dummy.envs[0])) == [True] * 3
    finally:
        workers.close()
        dummy.close()


class _InterruptOnce:
    """A worker connection whose first recv() is hit by Ctrl-C (as SIGTERM is in training)."""

    def __init__(self, remote) -> None:
        self.remote, self.fired = remote, False

    def recv(self):
        if not self.fired:
            self.fired = True
            raise KeyboardInterrupt
        return self.remote.recv()

    def __getattr__(self, name):
        return getattr(self.remote, name)


def test_close_after_an_interrupt_between_two_replies_does_not_hang():
    config = TrainConfig(envs=2)
    venv = WorkerVecEnv([make_env_fn(config, i) for i in range(2)], n_workers=2)
    venv.reset()
    venv.remotes[1] = _InterruptOnce(venv.remotes[1])
    venv.step_async(np.zeros((2, 6), dtype=np.float32))
    try:
        venv.step_wait()
    except KeyboardInterrupt:
        pass
    else:
        raise AssertionError("the interrupt did not reach step_wait")
    start = time.monotonic()
    venv.close()  # used to wait forever for the reply already read from the first worker
    assert time.monotonic() - start < 5
    assert not any(p.is_alive() for p in venv.processes)
