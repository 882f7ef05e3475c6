"""A privileged teacher distilled into a policy that sees only what a robot senses (DAgger).

The teacher is a run of ``rayreach train --privileged``: besides the rays it sees how near
each part of the arm is to the obstacles and how they move (``rayreach.sim.batch_clearance``),
which RL learns from much sooner than from 0.4 m rays. The student has the teacher's
observation without that part (``ObservationConfig.deployable``), its prefix, so one batched
env and the teacher's normalisation serve both. DAgger (Ross et al. 2011), as legged
locomotion's teacher-student training does it: the worlds are stepped by the teacher at
first and by the student more and more (``beta``), every visited state is labelled with the
teacher's action (its mean, clipped to the action bounds as the env would clip it) and value, and the student's actor and critic regress on an aggregate of
the latest labels. The student is saved as a training checkpoint of the default recipe, so
``rayreach train --resume`` fine-tunes it by PPO with the teacher's curricula.

``rayreach distill --teacher RUN/model.zip --out RUN2`` drives :func:`distill`; interrupted,
it saves the student and ``--resume`` goes on (with a fresh aggregate).
"""

from __future__ import annotations

import json
import signal
import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from rayreach.learning.bundles import CheckpointError, Normalization, read_bundle_meta, save_bundle

REPORT = "distill.json"
CURVE = "distill.csv"
CURVE_PNG = "distill.png"


@dataclass(frozen=True)
class DistillConfig:
    """One distillation; the defaults took a UR5 teacher's student to its level in minutes
    (docs/log/2026-12-07-levers-measured.md, "A privileged teacher")."""

    steps: int = 3_000_000
    """Environment steps stepped in all (worlds x steps per world)."""
    envs: int = 256
    rollout: int = 32
    """Steps of every world between two fits."""
    teacher_steps: int = 750_000
    """``beta``, the chance that a world is stepped by the teacher's action, falls linearly from
    1 to 0 over these first steps; after them the student drives."""
    buffer: int = 1_000_000
    """Labelled states kept, the oldest dropped (577 floats each: 2.3 GB)."""
    minibatch: int = 4096
    fits: int = 6
    """Minibatches drawn from the aggregate after each rollout."""
    learning_rate: float = 5e-4
    value_weight: float = 0.5
    """Weight of the critic's regression on the teacher's value (its normalised returns)."""
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("steps", "envs", "rollout", "buffer", "minibatch", "fits"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        if self.teacher_steps < 0:
            raise ValueError(f"teacher_steps must be >= 0, got {self.teacher_steps}")


def beta(step: int, teacher_steps: int) -> float:
    """The chance a world is stepped by the teacher after ``step`` steps of distillation."""
    return 0.0 if teacher_steps == 0 else max(0.0, 1.0 - step / teacher_steps)


def student_normalization(teacher: dict[str, np.ndarray], size: int) -> dict[str, np.ndarray]:
    """The teacher's VecNormalize arrays for the student's observation, its first ``size``
    values: the same statistics, so a student input is the teacher's input cut short."""
    out = dict(teacher)
    out["obs_mean"] = teacher["obs_mean"][:size].copy()
    out["obs_var"] = teacher["obs_var"][:size].copy()
    return out


class Aggregate:
    """The last ``capacity`` labelled states: student input, teacher action, teacher value."""

    def __init__(self, capacity: int, obs_size: int, action_size: int) -> None:
        self.obs = np.zeros((capacity, obs_size), dtype=np.float32)
        self.action = np.zeros((capacity, action_size), dtype=np.float32)
        self.value = np.zeros(capacity, dtype=np.float32)
        self.size = 0
        self.next = 0

    def add(self, obs: np.ndarray, action: np.ndarray, value: np.ndarray) -> None:
        rows = (self.next + np.arange(len(obs))) % len(self.obs)
        self.obs[rows], self.action[rows], self.value[rows] = obs, action, value
        self.next = int(rows[-1] + 1) % len(self.obs)
        self.size = min(self.size + len(obs), len(self.obs))

    def sample(self, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        rows = rng.integers(0, self.size, min(n, self.size))
        return self.obs[rows], self.action[rows], self.value[rows]


def distill(teacher_path: str | Path, out: str | Path, config: DistillConfig = DistillConfig(),
            resume: bool = False, command: str = "", progress: bool = True) -> Path:
    """Distil the teacher bundle into a student checkpoint at ``out/checkpoint.zip`` (and
    ``out/model.zip``, the student as it is, for rollouts); returns the checkpoint's path."""
    import torch
    from stable_baselines3 import PPO
    from tqdm import tqdm

    from rayreach.env.batched import BatchedReachEnv
    from rayreach.env.decisions import DecisionPeriod
    from rayreach.env.reach import episode_outcome
    from rayreach.learning.train import (CHECKPOINT, MODEL, TrainState, append_curve, build_model, bundle_meta,
                                         config_from_meta, env_config)

    teacher_path, out = Path(teacher_path), Path(out)
    meta, norm = read_bundle_meta(teacher_path)
    teacher_config = config_from_meta(meta)
    if not teacher_config.observation.privileged:
        raise CheckpointError(f"{teacher_path} is not a privileged teacher (train one with rayreach train --privileged)")
    normalize = Normalization.from_arrays(norm)
    if normalize is None or norm is None:
        raise CheckpointError(f"{teacher_path} carries no observation normalisation; the student inherits it")
    student_config = replace(teacher_config, observation=teacher_config.observation.deployable, recipe="default")
    checkpoint = out / CHECKPOINT
    done = 0
    if resume:
        if not checkpoint.exists():
            raise CheckpointError(f"--resume: no checkpoint at {checkpoint}")
        report = json.loads((out / REPORT).read_text())
        done = int(report["steps"])
    elif checkpoint.exists():
        raise CheckpointError(f"{checkpoint} exists: pass --resume to continue it, or choose another --out")
    else:
        report = {"teacher": str(teacher_path), "teacher_timesteps": int(meta["timesteps"]),
                  "teacher_wall_time_s": meta.get("wall_time_s"), "config": asdict(config), "command": command,
                  "steps": 0, "wall_time_s": 0.0}
    out.mkdir(parents=True, exist_ok=True)
    torch.manual_seed(config.seed + done)
    rng = np.random.default_rng(config.seed + done)
    env = BatchedReachEnv(teacher_config.robot, config.envs, scenario=teacher_config.suite,
                          config=env_config(teacher_config), seed=config.seed * 7_919 + done)
    state = TrainState.from_dict(meta["state"])
    state.best, state.validated_at = None, 0  # the student's own run chooses among its own checkpoints
    env.set_goal_tolerance(state.goal.size)
    env.set_n_obstacles(state.obstacles.count)
    size = env.observer.size
    stepper = DecisionPeriod(env, teacher_config.decision_period)  # the student decides as its teacher did
    teacher = PPO.load(str(teacher_path), device="cpu").policy
    model = (PPO.load(str(checkpoint), device="cpu") if resume
             else build_model(student_config, _student_view(env, size), None))
    student = model.policy
    student_norm = student_normalization(norm, size)
    optimiser = torch.optim.Adam(student.parameters(), lr=config.learning_rate)
    aggregate = Aggregate(config.buffer, size, 6)
    outcomes: list[str] = []
    started = time.perf_counter()
    wall_before = float(report["wall_time_s"])
    interrupted = False
    previous = signal.signal(signal.SIGTERM, _raise_interrupt)
    bar = tqdm(total=config.steps, initial=done, unit="step", desc="distill", disable=not progress, smoothing=0.05)
    raw = stepper.reset()
    try:
        while done < config.steps:
            share = beta(done, config.teacher_steps)
            for _ in range(config.rollout):
                x = normalize(raw)
                with torch.no_grad():
                    xt = torch.as_tensor(x)
                    label = teacher.get_distribution(xt).distribution.mean.numpy()
                    value = teacher.predict_values(xt).numpy()[:, 0]
                    own = student.get_distribution(xt[:, :size]).distribution.mean.numpy()
                aggregate.add(x[:, :size], np.clip(label, -1.0, 1.0), value)  # what the env would execute
                by_teacher = rng.random(config.envs) < share
                action = np.where(by_teacher[:, None], label, own)
                raw, _, dones, infos = stepper.step(np.clip(action, -1.0, 1.0))
                for i in np.flatnonzero(dones & ~by_teacher):  # the student's own episodes
                    outcomes.append(episode_outcome(infos[i]))
                done += config.envs
                bar.update(config.envs)
            losses = [_fit(student, optimiser, *aggregate.sample(config.minibatch, rng), config.value_weight)
                      for _ in range(config.fits)]
            recent = outcomes[-200:]
            row = {"steps": done, "wall_time": round(wall_before + time.perf_counter() - started, 1),
                   "beta": round(share, 3), "action_loss": round(float(np.mean([a for a, _ in losses])), 5),
                   "value_loss": round(float(np.mean([v for _, v in losses])), 5),
                   "student_episodes": len(outcomes),
                   "student_success_rate": round(recent.count("success") / len(recent), 4) if recent else "",
                   "student_collision_rate": round(recent.count("collision") / len(recent), 4) if recent else ""}
            append_curve(out / CURVE, row)
            bar.set_postfix(beta=f"{share:.2f}", loss=f"{row['action_loss']:.4f}",
                            success=row["student_success_rate"], refresh=False)
    except KeyboardInterrupt:
        interrupted = True
    finally:
        signal.signal(signal.SIGTERM, previous)
        bar.close()
        env.close()
    with torch.no_grad():  # the student explores as the teacher did when PPO takes over
        student.log_std.copy_(teacher.log_std)
    report["steps"] = done
    report["wall_time_s"] = round(wall_before + time.perf_counter() - started, 1)
    state.wall_time = report["wall_time_s"]
    state.distilled = report
    model.num_timesteps = 0
    student_meta = bundle_meta(student_config, state, 0, "checkpoint", size)
    save_bundle(model, checkpoint, student_meta, student_norm)
    save_bundle(model, out / MODEL, {**student_meta, "kind": "model", "command": command}, student_norm)
    (out / REPORT).write_text(json.dumps(report, indent=2) + "\n")
    plot_distillation(out / CURVE, out / CURVE_PNG)
    if interrupted:
        raise KeyboardInterrupt(f"interrupted at {done} steps; resume with --resume")
    return checkpoint


def plot_distillation(csv_path: Path, png_path: Path) -> Path | None:
    """The student's own episodes (success, collisions) and its fit to the teacher over the
    distillation's steps, with the teacher's share of the driving."""
    import csv

    from rayreach.learning.train import curve_figure, save_curve_figure

    with csv_path.open() as handle:
        rows = [r for r in csv.DictReader(handle)]
    if not rows:
        return None
    steps = np.array([float(r["steps"]) for r in rows]) / 1e6
    rate = {k: np.array([float(r[f"student_{k}_rate"] or "nan") for r in rows]) for k in ("success", "collision")}
    fig, ax1, ax2 = curve_figure()
    ax1.plot(steps, rate["success"], color="#2b9a3e", label="success (student's own episodes)")
    ax1.plot(steps, rate["collision"], color="#d62728", label="collision")
    ax1.plot(steps, [float(r["beta"]) for r in rows], color="#7f7f7f", linestyle="--", label="teacher's share of the driving")
    ax1.set_ylim(-0.02, 1.02)
    ax1.set_ylabel("share of last 200 episodes")
    ax1.set_title("distillation of a privileged teacher")
    ax1.legend(fontsize=8)
    ax1.grid(alpha=0.3)
    ax2.plot(steps, [float(r["action_loss"]) for r in rows], color="#1f5fd6")
    ax2.set_ylabel("action error (MSE)")
    return save_curve_figure(fig, ax2, png_path)


def _fit(policy, optimiser, obs: np.ndarray, action: np.ndarray, value: np.ndarray,
         value_weight: float) -> tuple[float, float]:
    """One minibatch: the actor's mean on the teacher's action, the critic on its value."""
    import torch

    x = torch.as_tensor(obs)
    action_loss = torch.nn.functional.mse_loss(policy.get_distribution(x).distribution.mean, torch.as_tensor(action))
    value_loss = torch.nn.functional.mse_loss(policy.predict_values(x)[:, 0], torch.as_tensor(value))
    optimiser.zero_grad()
    (action_loss + value_weight * value_loss).backward()
    optimiser.step()
    return float(action_loss.item()), float(value_loss.item())


def _raise_interrupt(signum, frame):
    raise KeyboardInterrupt


def _student_view(env, size: int) -> Any:
    """``env`` as a VecEnv of the student's observation (its first ``size`` values): what the
    student model is built against; distillation steps ``env`` itself."""
    import gymnasium as gym
    from stable_baselines3.common.vec_env import VecEnvWrapper

    class StudentView(VecEnvWrapper):
        def reset(self):
            return self.venv.reset()[:, :size]

        def step_wait(self):
            obs, rewards, dones, infos = self.venv.step_wait()
            return obs[:, :size], rewards, dones, infos

    space = env.observation_space
    return StudentView(env, observation_space=gym.spaces.Box(space.low[:size], space.high[:size], dtype=np.float32))
