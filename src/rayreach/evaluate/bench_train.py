"""Training throughput: the baseline recipe and the default, the same wall time each.

``rayreach bench-train --robot ur5 --seconds 120 --json`` trains each recipe in
``BENCH_RECIPES`` (both of ``rayreach.learning.train.RECIPES``) in turn, from scratch, into a
temporary directory, with the curricula at their start (random worlds with 1 obstacle, goal
0.1 m), the training callback, curve.csv and TensorBoard as in a real run, and no checkpoint
before the end.

samples/s counts whole PPO iterations (a rollout and its update) after a warm-up: building
the worlds, compiling the batched env and the first iteration are left out. The timed part
starts with the second rollout and ends with the first rollout begun after ``seconds``,
so it runs ``seconds`` plus up to one iteration.
"""

from __future__ import annotations

import tempfile
import time
from dataclasses import replace
from pathlib import Path
from typing import Any

from stable_baselines3.common.callbacks import BaseCallback

from rayreach.learning.train import TrainConfig, recipe, train

BENCH_RECIPES = ("baseline", "default")
"""Timed in this order: the baseline first, so that the default gains nothing from a warm cache."""


class PhaseTimer(BaseCallback):
    """Times collection and update of each iteration after the first and stops training at
    the first rollout begun after ``seconds`` of timing."""

    def __init__(self, seconds: float) -> None:
        super().__init__()
        self.seconds = seconds
        self.rollouts = self.iterations = 0
        self.start_time = self.start_steps = self.deadline = 0.0
        self.rollout_start = self.rollout_end = 0.0
        self.collect = self.update = 0.0
        self.stopped_at: tuple[float, int] | None = None

    def _on_rollout_start(self) -> None:
        now = time.perf_counter()
        self.rollouts += 1
        if self.rollouts == 2:  # the warm-up, the first rollout and update, is behind
            self.start_time, self.start_steps, self.deadline = now, self.num_timesteps, now + self.seconds
        elif self.rollouts > 2:
            self.update += now - self.rollout_end
            self.iterations += 1
            if now >= self.deadline:
                self.stopped_at = (now, self.num_timesteps)
        self.rollout_start = now

    def _on_rollout_end(self) -> None:
        self.rollout_end = time.perf_counter()
        if self.rollouts >= 2:
            self.collect += self.rollout_end - self.rollout_start

    def _on_step(self) -> bool:
        return self.stopped_at is None

    def result(self) -> dict[str, Any]:
        """The timed part: samples, seconds, iterations, collection and update seconds, samples/s."""
        if self.stopped_at is None:
            raise RuntimeError("training ended before the timed part did; give it more timesteps")
        end, steps = self.stopped_at
        samples, wall = steps - self.start_steps, end - self.start_time
        return {"samples": int(samples), "timed_s": round(wall, 2), "iterations": self.iterations,
                "collect_s": round(self.collect, 2), "update_s": round(self.update, 2),
                "samples_per_s": round(samples / wall, 1)}


def time_recipe(config: TrainConfig, seconds: float) -> dict[str, Any]:
    """Train ``config`` for about ``seconds`` after the warm-up; the timer's figures."""
    timer = PhaseTimer(seconds)
    config = replace(config, timesteps=10**12, checkpoint_every=10**12, validate_every=0, starts=1)  # the timer ends it
    with tempfile.TemporaryDirectory(prefix="rayreach-bench-train-") as out:
        train(config, Path(out) / "run", callbacks=[timer])
    return timer.result()


def bench_train(robot: str, seconds: float, configs: dict[str, TrainConfig] | None = None) -> dict[str, Any]:
    """samples/s of each recipe, its collection and update seconds, and the speedup of
    "default" over "baseline". ``configs`` (named as ``BENCH_RECIPES``) replaces the two
    recipes for ``robot``, e.g. with smaller ones."""
    if configs is None:
        configs = {name: recipe(name, robot=robot) for name in BENCH_RECIPES}
    phases = {name: time_recipe(config, seconds) for name, config in configs.items()}
    rates = {name: p["samples_per_s"] for name, p in phases.items()}
    return {"robot": robot, "seconds": seconds, "samples_per_s": rates,
            "speedup": round(rates["default"] / rates["baseline"], 3), "phases": phases,
            "warmup": "world construction and the first iteration excluded",
            "worlds": "random, curricula at their start (1 obstacle)"}
