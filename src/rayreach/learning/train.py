"""PPO training with the paper's hyperparameters and curricula, resumable from checkpoints.

``rayreach train --robot ur5 --timesteps N --out runs/NAME [--resume]`` drives
:func:`train`. Random worlds only: the experiments exp1..exp7 are the test set.
"""

from __future__ import annotations

import csv
import os
import platform
import signal
import subprocess
import time
from collections import deque
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any

import numpy as np

from rayreach.learning.curriculum import AugmentedGoalSize, GoalSizeParams, ObstacleCurriculum, ObstacleParams
from rayreach.learning.bundles import CheckpointError, read_bundle_meta, restore_normalization, save_bundle
from rayreach.env.rewards import RewardWeights

CHECKPOINT = "checkpoint.zip"
MODEL = "model.zip"
CURVE = "curve.csv"
CURVE_PNG = "learning_curve.png"
RECENT = 200
"""Episodes over which training rates are computed."""
REWARD_TERMS = tuple(f.name for f in fields(RewardWeights) if f.name != "proximity_range")


@dataclass(frozen=True)
class TrainConfig:
    """One training run. PPO values are the paper's table "Hyperparameter for training"
    unless marked; rollout sizes and the network are SB3-style choices the paper omits."""

    robot: str = "ur5"
    timesteps: int = 2_000_000
    envs: int = 32
    """Environments stepped in parallel (split over ``workers`` processes); many per worker
    amortise the fixed cost of each policy call and message (see docs/performance.md)."""
    workers: int = field(default_factory=lambda: os.cpu_count() or 1)
    """Worker processes; each steps envs / workers environments per message."""
    seed: int = 0
    gamma: float = 0.99
    batch_size: int = 256
    learning_rate: float = 3e-4
    clip_range: float = 0.2
    ent_coef: float = 0.0
    vf_coef: float = 0.5
    max_grad_norm: float = 0.5
    gae_lambda: float = 0.95
    max_episode_steps: int = 1024
    n_steps: int = 256
    """Steps per environment per rollout (not in the paper; 32 x 256 = 8,192 per update)."""
    n_epochs: int = 10
    features: tuple[int, ...] = (256, 256)
    """Shared feature extractor (actor and critic share it, as the paper says)."""
    heads: tuple[int, ...] = (128,)
    """Separate actor and critic layers on top of the shared features."""
    target_kl: float | None = 0.02
    """Stop an update's epochs early once the policy moved this far (SB3 ``target_kl``; not in
    the paper). Without it the approximate KL of an update grew to 0.7 as the action noise
    shrank, with 70 % of samples clipped (docs/training.md)."""
    share_features: bool = True
    """Actor and critic share the feature extractor (the paper); False gives each its own."""
    normalize: bool = True
    """Running normalisation of observations and rewards (VecNormalize); not in the paper."""
    progress_weight: float = 10.0
    """Weight of the progress term d_{t-1} - d_t; 0 is the paper's reward alone."""
    proximity_weight: float = -0.1
    """Weight of the proximity term (rays shorter than 0.1 m); 0 is the paper's reward alone."""
    shield_weight: float = 0.0
    """Weight of the shielded term (share of a step's translation the safety layer removed);
    only matters with ``acting_layers``."""
    true_goal_share: float = 0.5
    """Share of episodes played at the true goal size rho_min while the curriculum enlarges
    the goal (not in the paper; docs/training.md). They do not feed the goal-size curriculum."""
    acting_layers: bool = False
    """Play training episodes through the acting layers that reshape or refuse the policy's
    own step (``rayreach.acting.ActingConfig.training``: shield, workspace guard, arm's rule;
    not in the paper): collisions and exits the layers would stop become waits, which the
    policy must learn to go around. The layers that replace its action outright (final
    approach, detour, slide) stay out: PPO would store an action that had no effect on what
    followed (docs/acting.md, "Training with the layers")."""
    checkpoint_every: int = 100_000
    goal: GoalSizeParams = field(default_factory=GoalSizeParams)
    obstacles: ObstacleParams = field(default_factory=ObstacleParams)
    device: str = "cpu"


# ---------------------------------------------------------------------- model parts
def make_env_fn(config: TrainConfig, rank: int):
    """A thunk that builds one monitored random-world environment (picklable)."""

    def build():
        from stable_baselines3.common.monitor import Monitor

        from rayreach.env.reach import EnvConfig, ReachEnv
        from rayreach.scenarios.random_world import RandomWorldConfig

        env_config = EnvConfig(
            goal_tolerance=config.goal.rho,
            true_goal_share=config.true_goal_share,
            true_goal_tolerance=config.goal.rho_min,
            max_steps=config.max_episode_steps,
            rewards=replace(RewardWeights(), progress=config.progress_weight, proximity=config.proximity_weight,
                            shielded=config.shield_weight),
            random_world=RandomWorldConfig(n_obstacles=config.obstacles.start),
        )
        env = ReachEnv(robot=config.robot, scenario="random", config=env_config)
        if config.acting_layers:
            from rayreach.acting import ActingConfig, ActingEnv

            env = ActingEnv(env, ActingConfig.training())
        env.reset(seed=config.seed * 10_000 + rank)
        return Monitor(env, info_keywords=("is_success",))

    return build


def build_vec_env(config: TrainConfig):
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    from rayreach.learning.vec_env import WorkerVecEnv

    fns = [make_env_fn(config, i) for i in range(config.envs)]
    venv = DummyVecEnv(fns) if config.workers <= 1 else WorkerVecEnv(fns, config.workers)
    venv.seed(config.seed)
    if config.normalize:
        venv = VecNormalize(venv, norm_obs=True, norm_reward=True, clip_obs=10.0, gamma=config.gamma)
    return venv


def build_model(config: TrainConfig, venv, tensorboard_dir: str | None):
    from stable_baselines3 import PPO

    from rayreach.networks import SharedMLP

    policy_kwargs = {
        "features_extractor_class": SharedMLP,
        "features_extractor_kwargs": {"layers": tuple(config.features)},
        "share_features_extractor": config.share_features,
        "net_arch": {"pi": list(config.heads), "vf": list(config.heads)},
    }
    return PPO(
        "MlpPolicy",
        venv,
        learning_rate=config.learning_rate,
        n_steps=config.n_steps,
        batch_size=config.batch_size,
        n_epochs=config.n_epochs,
        gamma=config.gamma,
        gae_lambda=config.gae_lambda,
        clip_range=config.clip_range,
        ent_coef=config.ent_coef,
        vf_coef=config.vf_coef,
        max_grad_norm=config.max_grad_norm,
        target_kl=config.target_kl,
        policy_kwargs=policy_kwargs,
        tensorboard_log=tensorboard_dir,
        seed=config.seed,
        device=config.device,
        verbose=0,
    )


def set_trainable(policy, actor: bool = True, features: bool = True) -> None:
    """Freeze (or free) the actor's own layers and the feature extractor; the critic's own
    layers always learn.

    A checkpoint whose actor was just refitted by cloning has a critic that values the old
    actor, and through the shared extractor its first PPO updates would move the new actor
    on those stale advantages: ``train(critic_warmup=N)`` fits the critic alone first
    (``actor=False``, which holds the extractor too). ``train(freeze_features=True)`` keeps
    the extractor fixed for a whole part (``features=False``), so that the critic's value
    loss, which reaches the actor through shared features, cannot reshape them."""
    critic = [policy.mlp_extractor.value_net, policy.value_net]
    if not policy.share_features_extractor:
        critic.append(policy.vf_features_extractor)
    extractor = [policy.features_extractor, policy.pi_features_extractor]
    own = {id(p) for module in critic for p in module.parameters()}
    shared = {id(p) for module in extractor for p in module.parameters()} - own
    for p in policy.parameters():
        if id(p) in shared:
            p.requires_grad_(actor and features)
        elif id(p) not in own:
            p.requires_grad_(actor)


# ---------------------------------------------------------------------- bookkeeping
@dataclass
class TrainState:
    """What a checkpoint holds besides the model: curricula, wall time, its config."""

    goal: AugmentedGoalSize
    obstacles: ObstacleCurriculum
    wall_time: float = 0.0
    episodes: int = 0
    recent: deque = field(default_factory=lambda: deque(maxlen=RECENT))
    """Outcomes of the last episodes (for the rates shown and logged)."""
    recent_true: deque = field(default_factory=lambda: deque(maxlen=RECENT))
    """Outcomes of the last episodes played at the true goal size."""

    def rate(self, outcome: str, true_size: bool = False) -> float:
        recent = self.recent_true if true_size else self.recent
        return sum(o == outcome for o in recent) / len(recent) if recent else float("nan")

    def record(self, outcome: str, at_true_size: bool) -> None:
        self.episodes += 1
        self.recent.append(outcome)
        if at_true_size:
            self.recent_true.append(outcome)

    def to_dict(self) -> dict[str, Any]:
        return {
            "goal": self.goal.state(),
            "obstacles": self.obstacles.state(),
            "wall_time": self.wall_time,
            "episodes": self.episodes,
            "recent": list(self.recent),
            "recent_true": list(self.recent_true),
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "TrainState":
        return cls(
            AugmentedGoalSize.from_state(data["goal"]),
            ObstacleCurriculum.from_state(data["obstacles"]),
            float(data["wall_time"]),
            int(data["episodes"]),
            deque(data.get("recent", []), maxlen=RECENT),
            deque(data.get("recent_true", []), maxlen=RECENT),
        )


def update_threads(config: TrainConfig, available: int) -> int:
    """Torch threads for the PPO update: no more than the run's worker processes, the cores
    it was given. Two runs sharing two cores, each updating with two threads, ran at 170
    steps/s each, and at 1,500 to 1,800 with one thread each (docs/performance.md)."""
    return max(1, min(available, config.workers))


def _make_callback(config: TrainConfig, state: TrainState, out: Path, total: int, critic_warmup: int = 0,
                   freeze_features: bool = False):
    import torch
    from stable_baselines3.common.callbacks import BaseCallback
    from tqdm import tqdm

    from rayreach.env.reach import OUTCOMES, episode_outcome

    threads = update_threads(config, torch.get_num_threads())

    class TrainingCallback(BaseCallback):
        """Feeds episode outcomes to the curricula (one state for all envs), logs rates and
        reward terms, shows progress, writes curve.csv and checkpoints every interval."""

        def __init__(self) -> None:
            super().__init__()
            self.term_sums: list[dict[str, float]] = []
            self.finished_terms: deque[dict[str, float]] = deque(maxlen=RECENT)
            self.next_checkpoint = 0
            self.bar: Any = None
            self.t_start = 0.0
            self.wall_at_start = state.wall_time
            self.actor_frozen_until = 0

        def _on_rollout_start(self) -> None:
            torch.set_num_threads(1)  # intra-op threads spin and starve the env workers

        def _on_training_start(self) -> None:
            self.term_sums = [dict() for _ in range(self.training_env.num_envs)]
            self.next_checkpoint = (self.num_timesteps // config.checkpoint_every + 1) * config.checkpoint_every
            self.bar = tqdm(total=total, initial=self.num_timesteps, unit="step", dynamic_ncols=True,
                            desc=f"train {config.robot}", smoothing=0.05)
            self.t_start = time.time()
            self._push(goal=True, obstacles=True)
            if critic_warmup > 0:
                self.actor_frozen_until = self.num_timesteps + critic_warmup
            set_trainable(self.model.policy, actor=critic_warmup == 0, features=not freeze_features)

        def _push(self, goal: bool, obstacles: bool) -> None:
            if goal:
                self.training_env.env_method("set_goal_tolerance", state.goal.size)
            if obstacles:
                self.training_env.env_method("set_n_obstacles", state.obstacles.count)

        def _on_step(self) -> bool:
            infos = self.locals["infos"]
            dones = self.locals["dones"]
            size, count = state.goal.size, state.obstacles.count
            for i, (info, done) in enumerate(zip(infos, dones)):
                sums = self.term_sums[i]
                for key, value in info.get("reward_terms", {}).items():
                    sums[key] = sums.get(key, 0.0) + value
                if done:
                    success = bool(info.get("is_success"))
                    at_true_size = info.get("goal_tolerance", state.goal.size) <= state.goal.params.rho_min + 1e-9
                    if not info.get("true_goal_episode"):
                        state.goal.record(success)
                    state.obstacles.record(success, at_true_size=at_true_size)
                    state.record(episode_outcome(info), at_true_size)
                    self.finished_terms.append(dict(sums))
                    sums.clear()
            if state.goal.size != size or state.obstacles.count != count:
                self._push(goal=state.goal.size != size, obstacles=state.obstacles.count != count)
            self.bar.update(self.training_env.num_envs)
            if self.n_calls % 20 == 0 and state.recent:
                self.bar.set_postfix(success=f"{state.rate('success'):.2f}",
                                     true=f"{state.rate('success', true_size=True):.2f}", goal=f"{state.goal.size:.3f}",
                                     obstacles=state.obstacles.count, refresh=False)
            if self.num_timesteps >= self.next_checkpoint:
                self.save_checkpoint()
                self.next_checkpoint += config.checkpoint_every
            return True

        def _on_rollout_end(self) -> None:
            torch.set_num_threads(threads)  # the PPO update does gain from more cores
            if self.actor_frozen_until and self.num_timesteps >= self.actor_frozen_until:
                set_trainable(self.model.policy, actor=True, features=not freeze_features)
                self.actor_frozen_until = 0
            self.logger.record("train/actor_frozen", int(bool(self.actor_frozen_until)))
            row = {"timesteps": self.num_timesteps, "episodes": state.episodes,
                   "wall_time": round(self.wall_time(), 1), "goal_size": state.goal.size,
                   "obstacles": state.obstacles.count}
            for outcome in OUTCOMES:
                row[f"{outcome}_rate"] = round(state.rate(outcome), 4)
                self.logger.record(f"rollout/{outcome}_rate", row[f"{outcome}_rate"])
            for outcome in ("success", "collision"):
                row[f"true_{outcome}_rate"] = round(state.rate(outcome, true_size=True), 4)
                self.logger.record(f"rollout/true_{outcome}_rate", row[f"true_{outcome}_rate"])
            for key in REWARD_TERMS:  # mean per episode over the last finished episodes
                terms = [t.get(key, 0.0) for t in self.finished_terms]
                row[f"reward_{key}"] = round(float(np.mean(terms)), 4) if terms else float("nan")
                self.logger.record(f"reward/{key}", row[f"reward_{key}"])
            self.logger.record("curriculum/goal_size", state.goal.size)
            self.logger.record("curriculum/obstacles", state.obstacles.count)
            append_curve(out / CURVE, row)

        def wall_time(self) -> float:
            return self.wall_at_start + time.time() - self.t_start

        def save_checkpoint(self) -> None:
            state.wall_time = self.wall_time()
            save_bundle(self.model, out / CHECKPOINT, bundle_meta(config, state, self.num_timesteps, "checkpoint"),
                        self.model.get_vec_normalize_env())

        def _on_training_end(self) -> None:
            state.wall_time = self.wall_time()
            self.bar.close()

    return TrainingCallback()


def append_curve(path: Path, row: dict[str, Any]) -> None:
    """Append one row; a curve written by an older version gains the new columns (empty in
    its old rows) so that a resumed run keeps one consistent file."""
    fieldnames = list(row)
    if path.exists():
        with path.open(newline="") as handle:
            header = next(csv.reader(handle), [])
        if header != fieldnames:
            with path.open(newline="") as handle:
                rows = list(csv.DictReader(handle))
            fieldnames = header + [k for k in row if k not in header]
            with path.open("w", newline="") as handle:
                writer = csv.DictWriter(handle, fieldnames=fieldnames)
                writer.writeheader()
                writer.writerows(rows)
    new = not path.exists()
    with path.open("a", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=fieldnames, restval="")
        if new:
            writer.writeheader()
        writer.writerow(row)


def git_commit() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True, timeout=5,
                              cwd=Path(__file__).parent).stdout.strip() or "unknown"
    except (OSError, subprocess.SubprocessError):
        return "unknown"


def bundle_meta(config: TrainConfig, state: TrainState, steps: int, kind: str) -> dict[str, Any]:
    from rayreach.env.reach import OBS_SIZE

    return {
        "kind": kind,
        "robot": config.robot,
        "obs_shape": [OBS_SIZE],
        "timesteps": int(steps),
        "config": asdict(config),
        "state": state.to_dict(),
        "wall_time_s": round(state.wall_time, 1),
        "machine": f"{platform.node()} {platform.machine()} {os.cpu_count()} cores",
        "git_commit": git_commit(),
    }


def config_from_meta(meta: dict[str, Any]) -> TrainConfig:
    data = dict(meta["config"])
    data["goal"] = GoalSizeParams(**data["goal"])
    data["obstacles"] = ObstacleParams(**data["obstacles"])
    data["features"] = tuple(data["features"])
    data["heads"] = tuple(data["heads"])
    return TrainConfig(**data)


# ---------------------------------------------------------------------- entry point
def train(config: TrainConfig, out: str | Path, resume: bool = False, command: str = "",
          resume_overrides: dict[str, Any] | None = None, critic_warmup: int = 0,
          freeze_features: bool = False) -> Path:
    """Train (or resume) into ``out``; returns the path of the final model bundle.

    A resumed run keeps its saved configuration except ``timesteps``, ``workers`` and the
    fields named in ``resume_overrides`` (e.g. a new ``true_goal_share`` for a second part, or
    ``obstacles`` to hold the count, which restarts the obstacle curriculum).
    ``critic_warmup``: steps at the start of this part in which only the critic learns;
    ``freeze_features``: the feature extractor stays fixed for this part (``set_trainable``).
    A ``learning_rate`` in ``resume_overrides`` replaces the saved one."""
    if critic_warmup < 0:
        raise ValueError(f"critic_warmup must be >= 0 steps, got {critic_warmup}")
    out = Path(out)
    checkpoint = out / CHECKPOINT
    from stable_baselines3 import PPO

    if resume:
        if not checkpoint.exists():
            raise CheckpointError(f"--resume: no checkpoint at {checkpoint}")
        meta, norm = read_bundle_meta(checkpoint)
        if meta.get("kind") != "checkpoint":
            raise CheckpointError(f"{checkpoint} is a {meta.get('kind')} bundle, not a training checkpoint")
        saved = config_from_meta(meta)
        if saved.robot != config.robot:
            raise CheckpointError(f"{checkpoint} trains robot '{saved.robot}', not '{config.robot}'")
        config = replace(saved, timesteps=config.timesteps, workers=config.workers, **(resume_overrides or {}))
        state = TrainState.from_dict(meta["state"])
        if "obstacles" in (resume_overrides or {}):  # a new obstacle rule starts its own count
            state.obstacles = ObstacleCurriculum(config.obstacles)
    else:
        if checkpoint.exists():
            raise CheckpointError(f"{checkpoint} exists: pass --resume to continue it, or choose another --out")
        state = TrainState(AugmentedGoalSize(config.goal), ObstacleCurriculum(config.obstacles))
        norm = None

    out.mkdir(parents=True, exist_ok=True)
    venv = build_vec_env(config)
    try:
        tensorboard_dir = str(out / "tensorboard") if _has_tensorboard() else None
        if resume:
            model = PPO.load(str(checkpoint), env=venv, device=config.device, tensorboard_log=tensorboard_dir)
            model.learning_rate = config.learning_rate
            model._setup_lr_schedule()  # SB3 keeps the saved schedule otherwise
            if norm is not None:
                restore_normalization(venv, norm)
        else:
            model = build_model(config, venv, tensorboard_dir)
        remaining = config.timesteps - model.num_timesteps
        callback = _make_callback(config, state, out, config.timesteps, critic_warmup, freeze_features)
        interrupted = False
        if remaining > 0:
            previous = signal.getsignal(signal.SIGTERM)
            signal.signal(signal.SIGTERM, _raise_interrupt)
            try:
                model.learn(remaining, callback=callback, reset_num_timesteps=False, tb_log_name="ppo",
                            progress_bar=False)
            except KeyboardInterrupt:
                interrupted = True
            finally:
                signal.signal(signal.SIGTERM, previous)
            callback.save_checkpoint()  # the callback is bound to the model only once learn() ran
        if interrupted:
            raise KeyboardInterrupt(f"interrupted at {model.num_timesteps} steps; resume with --resume")
        meta = bundle_meta(config, state, model.num_timesteps, "model")
        meta["command"] = command
        path = save_bundle(model, out / MODEL, meta, model.get_vec_normalize_env())
        plot_curve(out / CURVE, out / CURVE_PNG, title=f"{config.robot.upper()} training")
        return path
    finally:
        venv.close()


def _raise_interrupt(signum, frame):  # SIGTERM behaves like Ctrl-C: checkpoint, then stop
    raise KeyboardInterrupt


def _has_tensorboard() -> bool:
    try:
        import tensorboard  # noqa: F401
    except ImportError:
        return False
    return True


def plot_curve(csv_path: Path, png_path: Path, title: str) -> Path | None:
    """The paper's training figure: success rate (and curricula) over environment steps."""
    if not csv_path.exists():
        return None
    import matplotlib

    matplotlib.use("Agg")
    from rayreach.env.reach import OUTCOMES
    import matplotlib.pyplot as plt

    with csv_path.open() as handle:
        rows = list(csv.DictReader(handle))
    if not rows:
        return None
    steps = np.array([float(r["timesteps"]) for r in rows]) / 1e6
    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(8, 6), sharex=True, gridspec_kw={"height_ratios": [2, 1]})
    for outcome, color in zip(OUTCOMES, ("#2b9a3e", "#d62728", "#ff7f0e", "#7f7f7f")):
        ax1.plot(steps, [float(r[f"{outcome}_rate"]) for r in rows], color=color, label=outcome.replace("_", " "))
    true_success = [float(r.get("true_success_rate") or "nan") for r in rows]
    if not np.all(np.isnan(true_success)):
        ax1.plot(steps, true_success, color="#2b9a3e", linestyle="--", label="success at the true goal size")
    ax1.set_ylabel("share of last 200 episodes")
    ax1.set_ylim(-0.02, 1.02)
    ax1.legend(loc="center right", fontsize=8)
    ax1.set_title(title)
    ax1.grid(alpha=0.3)
    ax2.plot(steps, [float(r["goal_size"]) for r in rows], color="#1f5fd6", label="goal size (m)")
    ax2.set_ylabel("goal size (m)")
    ax3 = ax2.twinx()
    ax3.step(steps, [float(r["obstacles"]) for r in rows], color="#8c564b", where="post", label="obstacles")
    ax3.set_ylabel("obstacles")
    ax2.set_xlabel("environment steps (millions)")
    ax2.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(png_path, dpi=110)
    plt.close(fig)
    return png_path

