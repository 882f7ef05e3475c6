"""PPO training with the paper's curricula, resumable from checkpoints.

``rayreach train --robot ur5 --timesteps N --out runs/NAME [--recipe NAME] [--resume]``
drives :func:`train`. Random worlds only: the experiments exp1..exp7 are the test set.
Two recipes (``RECIPES``): "default", many batched worlds with a few large minibatches
(the massively parallel recipe of Rudin et al. 2021), and "baseline", the per-environment
recipe with the paper's update that trained the shipped policies.
"""

from __future__ import annotations

import csv
import math
import os
import platform
import signal
import subprocess
import time
from collections import deque
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any, Sequence

import gymnasium as gym
import numpy as np

from rayreach.learning.imitation import DEMOS_GLOB, imitation_callback, load_demos
from rayreach.learning.curriculum import AugmentedGoalSize, GoalSizeParams, ObstacleCurriculum, ObstacleParams
from rayreach.learning.bundles import CheckpointError, read_bundle_meta, restore_normalization, save_bundle
from rayreach.learning import selection
from rayreach.learning.run_lock import held
from rayreach.env.decisions import check_period
from rayreach.env.observation import ObservationConfig
from rayreach.env.rewards import RewardWeights
from rayreach.scenarios import RANDOM, check_suite

CHECKPOINT = "checkpoint.zip"
MODEL = "model.zip"
CURVE = "curve.csv"
CURVE_PNG = "learning_curve.png"
RECENT = 200
"""Episodes over which training rates are computed."""
REWARD_TERMS = tuple(f.name for f in fields(RewardWeights) if f.type in (float, "float") and f.name != "proximity_range")
VEC_ENVS = ("batched", "workers")
"""How the worlds are stepped: one ``BatchedReachEnv`` for all, or one ``ReachEnv`` each."""
ACTING_ENVS = 64
"""Most worlds a run with acting layers may step (one ``ReachEnv`` and ``ActingEnv`` each)."""
LR_SCHEDULES = ("constant", "adaptive")
ADAPTIVE_LR_BOUNDS = (1e-5, 1e-2)
"""The adaptive schedule keeps the step size within these (rsl_rl's bounds)."""
ADAPTIVE_LR_FACTOR = 1.5


@dataclass(frozen=True)
class TrainConfig:
    """One training run; the defaults are the "default" recipe (``RECIPES``).

    PPO values are the paper's table "Hyperparameter for training" unless marked. The
    rollout and update sizes, the learning rate and the loss weights marked "rsl_rl" follow
    Rudin et al. 2021 ("Learning to walk in minutes using massively parallel deep RL", their
    rsl_rl PPO: 4 minibatches x 5 epochs, lr 1e-3 adapted to a KL of 0.01, value coefficient
    1.0, gradient norm 1.0). On two cores ``rayreach bench-train`` measured 6.3 to 6.9 times
    the baseline's samples per second (UR5, curricula at their start). There the update's cost
    grows with each epoch but hardly depends on the minibatch from 2,048 up, so four
    minibatches cost no more than one."""

    recipe: str = "default"
    """The ``RECIPES`` entry the run started from (its ``--recipe``)."""
    robot: str = "ur5"
    suite: str = RANDOM
    """The drawn worlds it trains in (``rayreach.scenarios.WORLD_SUITES``): "random", the
    paper's kind of scene in the robot's training box; "broad", a user's cell (tables,
    shelves, boxes, clutter, walls) up to the arm's reach (docs/environment.md)."""
    timesteps: int = 40_000_000
    """Decisions of the whole run: the UR5's 40 M took 1 h 29 min on two cores, the KR16's,
    after two starts of 5 M, about 1 h 55 min (docs/training.md, "Several starts")."""
    envs: int = 256
    """Worlds stepped in parallel (baseline: 32 environments split over ``workers``)."""
    vec_env: str = "batched"
    """One of ``VEC_ENVS``: "batched" steps all worlds in one ``BatchedReachEnv`` in this
    process; "workers" gives each world its own ``ReachEnv``, ``envs / workers`` of them in
    each of ``workers`` processes (the baseline). ``acting_layers`` always steps per world."""
    workers: int = field(default_factory=lambda: os.cpu_count() or 1)
    """Cores the run may use: worker processes of "workers" stepping, and torch threads of
    the update either way (``update_threads``)."""
    seed: int = 0
    gamma: float = 0.99
    batch_size: int = 4096
    """Minibatch (paper: 256): a quarter of a rollout, rsl_rl's 4 minibatches."""
    learning_rate: float = 1e-3
    """Adam step size (paper: 3e-4; rsl_rl: 1e-3); where ``lr_schedule`` adapts it, the start."""
    lr_schedule: str = "adaptive"
    """One of ``LR_SCHEDULES``. "adaptive" (rsl_rl's, not in the paper): after each update the
    step size is divided by 1.5 if the update's mean approximate KL exceeded twice
    ``desired_kl``, multiplied by 1.5 if it stayed under half, within ``ADAPTIVE_LR_BOUNDS``;
    the current value is part of the checkpoint's state."""
    desired_kl: float = 0.01
    """The adaptive schedule's target KL per update (rsl_rl's)."""
    clip_range: float = 0.2
    action_std_init: float = 1.0
    """Standard deviation of the policy's action noise at the start of a run, each action
    dimension (SB3's ``log_std_init`` of 0); a resumed run keeps its own, learned."""
    ent_coef: float = 0.0
    """The paper's (rsl_rl: 0.01). Kept: the shipped runs learned with it, and the goal's
    last centimetre wants the action noise to shrink."""
    vf_coef: float = 1.0
    """Value loss weight (paper: 0.5; rsl_rl: 1.0)."""
    max_grad_norm: float = 1.0
    """Gradient clip (paper: 0.5; rsl_rl: 1.0)."""
    gae_lambda: float = 0.95
    max_episode_steps: int = 1024
    n_steps: int = 64
    """Steps per world per rollout (not in the paper; 256 x 64 = 16,384 samples per update;
    rsl_rl: 24 steps of 4,096 worlds)."""
    n_epochs: int = 5
    """Passes over a rollout (paper: 10; rsl_rl: 5)."""
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
    collision_weight: float = -10.0
    """r_c, the reward of a collision (the paper's -10, the same as leaving the workspace)."""
    out_of_bounds_weight: float = -10.0
    """r_o, the reward of leaving the workspace (the paper's -10). A heavier collision cost
    alone makes leaving the workspace the cheaper way out of a tight spot."""
    collision_margin: float = 0.0
    """Distance, m, within which coming to an obstacle ends a training episode as a collision
    (``EnvConfig.collision_margin``; not in the paper); 0: a penetration, as in evaluation.
    For the UR5's goal under a cover it bought no success (docs/log/2026-12-07-levers-measured.md,
    "A margin round the obstacles in training")."""
    progress_weight: float = 10.0
    """Weight of the progress term d_{t-1} - d_t; 0 is the paper's reward alone."""
    progress_around_obstacles: bool = False
    """Measure the progress term along the shortest way round the static obstacles
    (``rayreach.env.goal_field``; not in the paper): the straight line rewards stopping at a
    wall that stands before the goal."""
    proximity_weight: float = 0.0
    """Weight of the proximity term (rays shorter than 0.1 m); 0 is the paper's reward alone.
    The baseline's -0.1 made the default recipe's policies hover short of goals near a wall
    (40 of 200 validation worlds timed out against none without it, docs/training.md)."""
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
    followed (docs/acting.md, "Training with the layers"). The layers wrap each ``ReachEnv``,
    so the worlds are stepped per environment whatever ``vec_env`` says; each costs about
    56 MB and 0.5 s to build, so give it the baseline's 32."""
    extra_kinds: tuple[str, ...] = ()
    """Obstacle kinds drawn beside the robot's ``training_kinds``
    (``rayreach.scenarios.random_world.KINDS``; not in the paper): a kind listed again is
    drawn more often in training. The evaluation suites keep the robot's own kinds."""
    cover_speed: tuple[float, float] | None = None
    """Speed range, m/s, of the training worlds' goal covers (``RandomWorldConfig.cover_speed``;
    not in the paper); None: the suites' 0.05-0.2 m/s. The evaluation suites keep theirs."""
    observation: ObservationConfig = ObservationConfig.planner()
    """What the policy sees beyond the paper's 142 values (``rayreach.env.observation``; not in
    the paper): the goal's direction, the workspace's walls, its own motion and three ray
    scans of the last 24 steps."""
    decision_period: int = 4
    """Control steps each action is held for (``rayreach.env.decisions``; not in the paper,
    whose agent decides every control step: the paper and baseline recipes' 1). Four took the
    UR5 alone from 83.0 to 89.5 % of validation worlds at equal wall time, collisions from 12.0
    to 7.5 % (docs/training.md, "How often the policy decides"). ``timesteps``, ``n_steps``
    and the rates of ``curve.csv`` count decisions; ``max_episode_steps`` counts control steps."""
    checkpoint_every: int = 100_000
    validate_every: int = 2_500_000
    """Decisions between validations of the checkpoint alone on ``validate_worlds`` validation
    worlds, the best kept as best.zip (``rayreach.learning.selection``; not in the paper); 0:
    never. A run shorter than one interval chooses nothing; one that validated judges its
    last checkpoint too. A run saved before runs validated resumes with 0."""
    validate_worlds: int = 500
    """Worlds of each validation (a resumed part that changes it starts its choice afresh)."""
    starts: int = 1
    """Seeds started side by side (``seed``, ``seed + 1``, ...), each on ``workers // starts``
    cores for ``start_decisions`` decisions; the one that scores best alone on the selection
    worlds continues the run (``rayreach.learning.starts``; not in the paper)."""
    start_decisions: int = 5_000_000
    """Decisions of each start before the choice."""
    clone_at: int = 0
    """Decisions after which the scripted experts of ``clone_kinds`` are cloned into the actor,
    and PPO goes on from the clone (``rayreach.learning.clone_stage``; not in the paper); 0: never."""
    clone_kinds: tuple[str, ...] = ()
    """World kinds whose expert is cloned at ``clone_at``, in order
    (``rayreach.learning.demonstrations.clonable_kinds`` of the robot and suite)."""
    imitation_steps: int = 0
    """Behaviour-cloning steps (256 samples each) on the run's recorded demonstrations before
    each rollout, an imitation term beside PPO's loss (``rayreach.learning.imitation``; not in
    the paper); 0: none. They need a clone first, and start once the actor learns."""
    goal: GoalSizeParams = field(default_factory=GoalSizeParams)
    obstacles: ObstacleParams = field(default_factory=ObstacleParams)
    device: str = "cpu"

    def __post_init__(self) -> None:
        check_suite(self.suite)
        if self.vec_env not in VEC_ENVS:
            raise ValueError(f"vec_env must be one of {', '.join(VEC_ENVS)}; got {self.vec_env!r}")
        if self.acting_layers and self.envs > ACTING_ENVS:
            raise ValueError(f"with acting layers each of the {self.envs} worlds is its own ReachEnv (about 56 MB "
                             f"and 0.5 s to build); give it {ACTING_ENVS} or fewer (--envs, or --recipe baseline: 32)")
        if self.observation.privileged and not self.batched:
            raise ValueError("a privileged observation (a teacher's) is computed by the batched env only: "
                             "vec_env 'batched' without acting layers")
        check_period(self.decision_period)
        if not self.action_std_init > 0:
            raise ValueError(f"action_std_init must be > 0, got {self.action_std_init}")
        if self.checkpoint_every < 1:
            raise ValueError(f"checkpoint_every must be >= 1 decision, got {self.checkpoint_every}")
        if self.validate_every < 0 or self.validate_worlds < 1:
            raise ValueError(f"validate_every must be >= 0 (0: never) and validate_worlds >= 1; "
                             f"got {self.validate_every} and {self.validate_worlds}")
        if self.starts < 1 or self.start_decisions < 1:
            raise ValueError(f"starts and start_decisions must be >= 1; got {self.starts} and {self.start_decisions}")
        if self.clone_at < 0 or bool(self.clone_kinds) != (self.clone_at > 0):
            raise ValueError(f"clone_at must be > 0 with clone_kinds and 0 without; got {self.clone_at} with "
                             f"{self.clone_kinds or 'no kinds'}")
        if self.imitation_steps < 0:
            raise ValueError(f"imitation_steps must be >= 0 (0: none); got {self.imitation_steps}")
        if self.clone_kinds and self.starts > 1 and self.start_decisions >= self.clone_at:
            raise ValueError(f"{self.starts} starts of {self.start_decisions} decisions each end after the clone at "
                             f"{self.clone_at}: give start_decisions below clone_at, or one start")
        if self.clone_kinds:
            from rayreach.learning.demonstrations import clonable_kinds

            known = clonable_kinds(self.robot, self.suite)
            unknown = [k for k in self.clone_kinds if k not in known]
            if unknown:
                raise ValueError(f"no expert of {', '.join(unknown)} for the {self.robot} in the {self.suite} suite; "
                                 f"clone_kinds can name: {', '.join(known)}")
        if self.extra_kinds:  # the check imports the world generator, which the recipes at import time need not
            from rayreach.scenarios.random_world import check_kinds

            check_kinds(self.extra_kinds, " in extra_kinds")
        if self.cover_speed is not None:
            from rayreach.scenarios.random_world import RandomWorldConfig

            RandomWorldConfig(cover_speed=self.cover_speed)  # checks the bounds
        if self.collision_margin:
            from rayreach.env.reach import EnvConfig

            EnvConfig(collision_margin=self.collision_margin)  # checks the bounds
        if self.lr_schedule not in LR_SCHEDULES:
            raise ValueError(f"lr_schedule must be one of {', '.join(LR_SCHEDULES)}; "
                             f"got {self.lr_schedule!r}")

    @property
    def batched(self) -> bool:
        """All worlds in one ``BatchedReachEnv`` (else one ``ReachEnv`` per world)."""
        return self.vec_env == "batched" and not self.acting_layers


PAPER_PPO = {"batch_size": 256, "learning_rate": 3e-4, "lr_schedule": "constant", "vf_coef": 0.5,
             "max_grad_norm": 0.5, "n_steps": 256, "n_epochs": 10, "decision_period": 1}
"""The paper's table "Hyperparameter for training" (and SB3's 10 epochs, which the paper's
code used), over 32 worlds x 256 steps: 8,192 samples per update, a decision every control
step."""

RECIPES: dict[str, TrainConfig] = {
    "default": TrainConfig(),
    "baseline": TrainConfig(recipe="baseline", envs=32, vec_env="workers", observation=ObservationConfig(),
                            timesteps=20_000_000, proximity_weight=-0.1, validate_every=0, **PAPER_PPO),
    "paper": TrainConfig(recipe="paper", envs=32, timesteps=20_000_000, observation=ObservationConfig(),
                         normalize=False, progress_weight=0.0, proximity_weight=0.0, true_goal_share=0.0,
                         target_kl=None, validate_every=0, **PAPER_PPO),
}
"""Named starting points of a run. "default": the planner's observation on batched worlds
with rsl_rl's large-batch update. "baseline": the recipe of the shipped runs, 32 worlds in
``workers`` processes and the paper's PPO values with the shaping the shipped runs added
(observation and reward normalisation, progress and proximity terms, true-size episodes,
``target_kl``). "paper": the paper's agent as published, its 142 values, reward, PPO values
and curricula and nothing else (stepped in one ``BatchedReachEnv``, the same MDP). Only the
default recipe chooses its best checkpoint on validation worlds."""


DEFAULT_BY_ROBOT: dict[str, dict[str, Any]] = {
    "kr16": {"observation": replace(ObservationConfig.planner(), tip_back=False), "starts": 2},
    "ur5": {"action_std_init": 0.3},
}
"""Where the default recipe differs by robot, each from measurements on validation worlds
(docs/training.md): the tip-back rays took the UR5 alone from 76.5 to 85.5 % and the KR16,
whose worlds hold no cover, from 61.0 down to 53.0 % ("The goal under a cover"). The KR16
starts two seeds: one of its four runs never learned to enter the shelf, and showed it by 5 M
decisions ("A second KR16 run: the shelf"). The UR5 starts with less action noise, 0.3 of
a full step: two seeds from scratch stood 2.9 and 5.0 points above the recipe's 1.0 alone
on 1,000 validation worlds at 40 M, with paths a tenth of a metre shorter ("Less action
noise"). Both run 40 M decisions, the most that fit two hours on two cores with the KR16's
starts: its first run gained two points alone between 40 and 50 M, its seed 1 scored best
at 20 M and no better to 40 M ("Several starts")."""


DEFAULT_BY_SUITE: dict[str, dict[str, Any]] = {
    "broad": {"timesteps": 16_000_000, "clone_at": 5_000_000, "clone_kinds": ("goal_box", "shelf"), "starts": 1,
              "obstacles": ObstacleParams(start=3, minimum=3, maximum=3, mix=True)},
}
"""Where the default recipe differs by suite. In broad worlds PPO alone learned the tables and
hardly the open boxes or shelves: 12 of 104 boxes and 9 of 114 shelves alone at 12.8 M
decisions, against 75 and 54 after their experts were cloned at 6.4 M (docs/training.md,
"Broad worlds"). 16 M decisions with the clone took the UR5 2 h 27 min on two cores, shared
with other work for part of it (docs/training.md, "Broad worlds"). One
start: the KR16's second start was measured for its shelf in random worlds, and the clone
teaches the shelf here. The worlds hold 1, 2 and 3 elements in turn (``ObstacleParams.mix``):
the obstacle curriculum kept a run on one element for 80 % of its decisions, and with the mix
the UR5 alone reached 36.8 % of three-element validation worlds at 16 M against 24.2 %
("An even mix of element counts")."""


def recipe(name: str, **changes: Any) -> TrainConfig:
    """The recipe ``name`` for ``changes["robot"]`` and ``changes["suite"]``
    (``DEFAULT_BY_ROBOT``, ``DEFAULT_BY_SUITE``) with ``changes`` (TrainConfig fields) applied."""
    if name not in RECIPES:
        raise ValueError(f"unknown recipe {name!r}; choose one of {', '.join(RECIPES)}")
    base = RECIPES[name]
    defaults: dict[str, Any] = {}
    if name == "default":
        defaults = {**DEFAULT_BY_ROBOT.get(changes.get("robot", base.robot), {}),
                    **DEFAULT_BY_SUITE.get(changes.get("suite", base.suite), {})}
    return replace(base, **{**defaults, **changes})


def with_envs(config: TrainConfig, envs: int) -> TrainConfig:
    """``config`` with ``envs`` worlds and the same minibatch, or one rollout's worth where
    a rollout of so few worlds is smaller (the baseline's 256 fits any count)."""
    if envs < 1:
        raise ValueError(f"envs must be >= 1, got {envs}")
    return replace(config, envs=envs, batch_size=min(config.batch_size, envs * config.n_steps))


# ---------------------------------------------------------------------- model parts
def training_kinds(config: TrainConfig) -> tuple[str, ...] | None:
    """The obstacle kinds a run draws its worlds from: the robot's with ``extra_kinds`` added
    (None, the robot's own, where it adds none)."""
    if not config.extra_kinds:
        return None
    from rayreach.robots import get_robot

    return get_robot(config.robot).training_kinds + config.extra_kinds


def env_config(config: TrainConfig):
    """The ``EnvConfig`` of every training world: curriculum start, reward weights, step budget."""
    from rayreach.env.reach import EnvConfig
    from rayreach.scenarios.random_world import RandomWorldConfig

    return EnvConfig(
        goal_tolerance=config.goal.rho,
        true_goal_share=config.true_goal_share,
        true_goal_tolerance=config.goal.rho_min,
        max_steps=config.max_episode_steps,
        rewards=replace(RewardWeights(), collision=config.collision_weight,
                        out_of_bounds=config.out_of_bounds_weight, progress=config.progress_weight,
                        proximity=config.proximity_weight, shielded=config.shield_weight,
                        progress_around_obstacles=config.progress_around_obstacles),
        random_world=RandomWorldConfig(n_obstacles=config.obstacles.start, kinds=training_kinds(config),
                                       cover_speed=config.cover_speed),
        observation=config.observation,
        collision_margin=config.collision_margin,
    )


class ShieldedEpisodeTerm(gym.Wrapper):
    """Adds the episode's sum of ``ActingEnv``'s "shielded" term to the last info's
    ``episode_reward_terms``: the ``ReachEnv`` sums its own terms inside its step, before
    ``ActingEnv`` adds this one, and the training callback reads terms there only."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.shielded = 0.0

    def reset(self, **kwargs):
        self.shielded = 0.0
        return self.env.reset(**kwargs)

    def step(self, action):
        obs, reward, terminated, truncated, info = self.env.step(action)
        self.shielded += info["reward_terms"]["shielded"]
        if terminated or truncated:
            info["episode_reward_terms"]["shielded"] = self.shielded
        return obs, reward, terminated, truncated, info


def make_env_fn(config: TrainConfig, rank: int):
    """A thunk that builds one monitored environment of the config's suite (picklable)."""

    def build():
        from stable_baselines3.common.monitor import Monitor

        from rayreach.env.reach import ReachEnv

        env = ReachEnv(robot=config.robot, scenario=config.suite, config=env_config(config))
        if config.acting_layers:
            from rayreach.acting import ActingConfig, ActingEnv

            env = ShieldedEpisodeTerm(ActingEnv(env, ActingConfig.training()))
        if config.decision_period > 1:
            from rayreach.env.decisions import HeldAction

            env = HeldAction(env, config.decision_period)
        env.reset(seed=config.seed * 10_000 + rank)
        return Monitor(env, info_keywords=("is_success",))

    return build


def batched_vec_env(config: TrainConfig):
    """All worlds in one ``BatchedReachEnv``, with SB3's ``VecMonitor`` for episode returns
    and lengths (a per-world ``Monitor`` needs a per-world env)."""
    from stable_baselines3.common.vec_env import VecMonitor

    from rayreach.env.batched import BatchedReachEnv
    from rayreach.env.decisions import DecisionPeriod

    venv = BatchedReachEnv(config.robot, config.envs, scenario=config.suite, config=env_config(config),
                           seed=config.seed)
    if config.decision_period > 1:
        venv = DecisionPeriod(venv, config.decision_period)
    return VecMonitor(venv, info_keywords=("is_success",))


def per_env_vec_env(config: TrainConfig):
    """One ``ReachEnv`` per world: in this process with one worker, else in ``WorkerVecEnv``."""
    from stable_baselines3.common.vec_env import DummyVecEnv

    from rayreach.learning.vec_env import WorkerVecEnv

    fns = [make_env_fn(config, i) for i in range(config.envs)]
    return DummyVecEnv(fns) if config.workers <= 1 else WorkerVecEnv(fns, config.workers)


def build_vec_env(config: TrainConfig):
    """The training worlds as ``config.vec_env`` steps them, normalised if asked."""
    from stable_baselines3.common.vec_env import VecNormalize

    venv = batched_vec_env(config) if config.batched else per_env_vec_env(config)
    venv.seed(config.seed)
    if config.normalize:
        venv = VecNormalize(venv, norm_obs=True, norm_reward=True, clip_obs=10.0, gamma=config.gamma)
    return venv


def build_model(config: TrainConfig, venv, tensorboard_dir: str | None):
    from stable_baselines3 import PPO

    from rayreach.networks import SharedMLP

    rollout = config.envs * config.n_steps
    if config.batch_size > rollout:
        raise ValueError(f"batch_size {config.batch_size} exceeds a rollout of envs {config.envs} x n_steps "
                         f"{config.n_steps} = {rollout} samples; give at most {rollout}")

    policy_kwargs = {
        "features_extractor_class": SharedMLP,
        "features_extractor_kwargs": {"layers": tuple(config.features)},
        "share_features_extractor": config.share_features,
        "net_arch": {"pi": list(config.heads), "vf": list(config.heads)},
        "log_std_init": math.log(config.action_std_init),
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
    learning_rate: float | None = None
    """The adaptive schedule's step size now (None: not adapted yet, the config's)."""
    distilled: dict[str, Any] | None = None
    """Where the run started as a student of a privileged teacher: the distillation's report
    (``rayreach.learning.distill``); PPO went on from it."""
    best: dict[str, Any] | None = None
    """The best validation so far (a validation.csv row), the checkpoint kept as best.zip."""
    validated_at: int = 0
    """Decisions at the last validation."""

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
            "learning_rate": self.learning_rate,
            "distilled": self.distilled,
            "best": self.best,
            "validated_at": self.validated_at,
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
            data.get("learning_rate"),
            data.get("distilled"),
            data.get("best"),
            int(data.get("validated_at", 0)),
        )


def update_threads(config: TrainConfig, available: int) -> int:
    """Torch threads for the PPO update: no more than the run's worker processes, the cores
    it was given. Two runs sharing two cores, each updating with two threads, ran at 170
    steps/s each, and at 1,500 to 1,800 with one thread each (docs/performance.md)."""
    return max(1, min(available, config.workers))


def adapted_learning_rate(lr: float, kl: float, desired_kl: float) -> float:
    """rsl_rl's rule for the next update's step size from the last update's mean KL."""
    if kl > 2.0 * desired_kl:
        lr /= ADAPTIVE_LR_FACTOR
    elif kl < desired_kl / 2.0:
        lr *= ADAPTIVE_LR_FACTOR
    low, high = ADAPTIVE_LR_BOUNDS
    return min(max(lr, low), high)


def set_discount(model, gamma: float) -> None:
    """The discount of the next rollouts' returns and advantages (SB3 keeps the saved one);
    the reward normalisation's, ``build_vec_env``, follows the config already."""
    model.gamma = gamma
    model.rollout_buffer.gamma = gamma


def set_learning_rate(model, lr: float) -> None:
    """A constant step size from the next update on (SB3 would keep the saved schedule)."""
    model.learning_rate = lr
    model._setup_lr_schedule()


def next_multiple(steps: int, every: int) -> int:
    """The first multiple of ``every`` past ``steps``: when a periodic task next falls due."""
    return (steps // every + 1) * every


def _make_callback(config: TrainConfig, state: TrainState, out: Path, total: int, critic_warmup: int = 0,
                   freeze_features: bool = False):
    import torch
    from stable_baselines3.common.callbacks import BaseCallback
    from tqdm import tqdm

    from rayreach.env.reach import OUTCOMES, episode_outcome

    threads = update_threads(config, torch.get_num_threads())

    class TrainingCallback(BaseCallback):
        """Feeds episode outcomes to the curricula (one state for all worlds), logs rates and
        reward terms, adapts the step size, shows progress, writes curve.csv and checkpoints
        every interval. A step only looks at the worlds whose episode ended: infos of the
        others may be empty, and with 256 worlds a look at each would cost more than the rest."""

        def __init__(self) -> None:
            super().__init__()
            self.finished_terms: deque[dict[str, float]] = deque(maxlen=RECENT)
            self.next_checkpoint = 0
            self.next_validation = 0
            self.bar: Any = None
            self.t_start = 0.0
            self.wall_at_start = state.wall_time
            self.actor_frozen_until = 0

        def _on_rollout_start(self) -> None:
            torch.set_num_threads(1)  # intra-op threads spin and starve the env workers

        def _on_training_start(self) -> None:
            self.next_checkpoint = next_multiple(self.num_timesteps, config.checkpoint_every)
            if config.validate_every:  # from the last validation: one cut short is made at once
                self.next_validation = next_multiple(state.validated_at, config.validate_every)
            self.bar = tqdm(total=total, initial=self.num_timesteps, unit="step", dynamic_ncols=True,
                            desc=f"train {config.robot}", smoothing=0.05)
            self.t_start = time.time()
            self._push(goal=True, obstacles=True)
            if critic_warmup > 0:
                self.actor_frozen_until = self.num_timesteps + critic_warmup
            set_trainable(self.model.policy, actor=critic_warmup == 0, features=not freeze_features)
            if config.lr_schedule == "adaptive":
                set_learning_rate(self.model, state.learning_rate or config.learning_rate)

        def _push(self, goal: bool, obstacles: bool) -> None:
            if goal:
                self.training_env.env_method("set_goal_tolerance", state.goal.size)
            if obstacles:
                counts = state.obstacles.params.world_counts(state.obstacles.count, self.training_env.num_envs)
                for count in sorted(set(counts)):
                    self.training_env.env_method("set_n_obstacles", count,
                                                 indices=[i for i, c in enumerate(counts) if c == count])

        def _on_step(self) -> bool:
            ended = np.flatnonzero(self.locals["dones"])
            if ended.size:
                self._episodes_ended([self.locals["infos"][i] for i in ended])
            self.bar.update(self.training_env.num_envs)
            if self.n_calls % 20 == 0 and state.recent:
                self.bar.set_postfix(success=f"{state.rate('success'):.2f}",
                                     true=f"{state.rate('success', true_size=True):.2f}", goal=f"{state.goal.size:.3f}",
                                     obstacles=state.obstacles.count, refresh=False)
            if self.num_timesteps >= self.next_checkpoint:
                self.save_checkpoint()
                self.next_checkpoint += config.checkpoint_every
            if config.validate_every and self.num_timesteps >= self.next_validation:
                self.validate()
                self.next_validation = next_multiple(self.num_timesteps, config.validate_every)
            return True

        def _episodes_ended(self, infos: list[dict[str, Any]]) -> None:
            """Each last info to the curricula and rates; new curriculum values to all worlds."""
            size, count = state.goal.size, state.obstacles.count
            for info in infos:
                success = bool(info.get("is_success"))
                at_true_size = info.get("goal_tolerance", state.goal.size) <= state.goal.params.rho_min + 1e-9
                if not info.get("true_goal_episode"):
                    state.goal.record(success)
                state.obstacles.record(success, at_true_size=at_true_size)
                state.record(episode_outcome(info), at_true_size)
                self.finished_terms.append(info.get("episode_reward_terms", {}))
            if state.goal.size != size or state.obstacles.count != count:
                self._push(goal=state.goal.size != size, obstacles=state.obstacles.count != count)

        def _on_rollout_end(self) -> None:
            torch.set_num_threads(threads)  # the PPO update does gain from more cores
            if config.lr_schedule == "adaptive" and not self.actor_frozen_until:
                self._adapt_learning_rate()  # a held actor's KL of 0 would only drive the step size up
            if self.actor_frozen_until and self.num_timesteps >= self.actor_frozen_until:
                set_trainable(self.model.policy, actor=True, features=not freeze_features)
                self.actor_frozen_until = 0
            self.logger.record("train/actor_frozen", int(bool(self.actor_frozen_until)))
            row = {"timesteps": self.num_timesteps, "episodes": state.episodes,
                   "wall_time": round(self.wall_time(), 1), "goal_size": state.goal.size,
                   "obstacles": state.obstacles.count, "learning_rate": self.model.learning_rate}
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

        def _adapt_learning_rate(self) -> None:
            """The step size for the coming update from the last one's KL. SB3 records that KL
            in ``train()`` and writes it out only after this rollout, so it is still there
            (absent before a part's first update, which then keeps the step size)."""
            kl = self.logger.name_to_value.get("train/approx_kl")
            if kl is not None:
                lr = adapted_learning_rate(self.model.learning_rate, float(kl), config.desired_kl)
                state.learning_rate = lr
                set_learning_rate(self.model, lr)

        def wall_time(self) -> float:
            return self.wall_at_start + time.time() - self.t_start

        def save_checkpoint(self) -> None:
            state.wall_time = self.wall_time()
            save_bundle(self.model, out / CHECKPOINT, bundle_meta(config, state, self.num_timesteps, "checkpoint",
                                    self.model.observation_space.shape[0]),
                        self.model.get_vec_normalize_env())

        def validate(self) -> None:
            """Play the checkpoint of now on the selection worlds; keep it as best.zip if it
            scores best so far. The checkpoint is saved again so that it holds the verdict. A
            validation that fails is reported and skipped: it must not end hours of training."""
            self.save_checkpoint()
            try:
                verdict = selection.validate(out / CHECKPOINT, config.robot, config.suite, config.validate_worlds)
            except Exception as exc:  # noqa: BLE001 - any failure of the judge, reported
                self.bar.write(f"validation at {self.num_timesteps:,} failed, skipped: {exc!r}")
                return
            row = {"timesteps": self.num_timesteps, "wall_time": round(self.wall_time(), 1), **verdict}
            append_curve(out / selection.VALIDATION_CSV, row)
            state.validated_at = self.num_timesteps
            better = selection.beats(row, state.best)
            if better:
                state.best = row
            self.save_checkpoint()
            if better:
                selection.keep_best(out, out / CHECKPOINT)
            self.logger.record("validation/success_rate", row["success_rate"])
            self.logger.record("validation/collision_rate", row["collision_rate"])
            self.bar.write(f"validation at {self.num_timesteps:,}: success {row['success_rate']:.3f}, collisions "
                           f"{row['collision_rate']:.3f} (best at {state.best['timesteps']:,}: {state.best['score']:.3f})")

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


def bundle_meta(config: TrainConfig, state: TrainState, steps: int, kind: str, obs_size: int) -> dict[str, Any]:
    return {
        "kind": kind,
        "robot": config.robot,
        "obs_shape": [int(obs_size)],
        "timesteps": int(steps),
        "config": asdict(config),
        "state": state.to_dict(),
        "wall_time_s": round(state.wall_time, 1),
        "machine": f"{platform.node()} {platform.machine()} {os.cpu_count()} cores",
        "git_commit": git_commit(),
    }


def config_from_meta(meta: dict[str, Any]) -> TrainConfig:
    """The config a bundle was trained with. A field its meta lacks came after the run was
    made, under the baseline recipe: it takes the baseline's value (the behaviour then)."""
    data = dict(meta["config"])
    for f in fields(TrainConfig):
        data.setdefault(f.name, getattr(RECIPES["baseline"], f.name))
    data["goal"] = GoalSizeParams(**data["goal"])
    data["obstacles"] = ObstacleParams(**data["obstacles"])
    if isinstance(data["observation"], dict):
        data["observation"] = ObservationConfig(**data["observation"])
    data["features"] = tuple(data["features"])
    data["heads"] = tuple(data["heads"])
    data["extra_kinds"] = tuple(data["extra_kinds"])
    data["clone_kinds"] = tuple(data["clone_kinds"])
    if data["cover_speed"] is not None:
        data["cover_speed"] = tuple(data["cover_speed"])
    return TrainConfig(**data)


# ---------------------------------------------------------------------- entry point
def train(config: TrainConfig, out: str | Path, resume: bool = False, command: str = "",
          resume_overrides: dict[str, Any] | None = None, critic_warmup: int = 0,
          freeze_features: bool = False, callbacks: Sequence[Any] = ()) -> Path:
    """Train (or resume) into ``out``; returns the path of the final model bundle.

    A resumed run keeps its saved configuration except ``timesteps``, ``workers`` and the
    fields named in ``resume_overrides`` (e.g. a new ``true_goal_share`` for a second part, or
    ``obstacles`` to hold the count, which restarts the obstacle curriculum).
    ``critic_warmup``: steps at the start of this part in which only the critic learns;
    ``freeze_features``: the feature extractor stays fixed for this part (``set_trainable``).
    A ``learning_rate`` in ``resume_overrides`` replaces the saved one (and restarts an
    adaptive schedule from it). ``callbacks``: more SB3 callbacks beside the training one
    (bench-train's timer); one that returns False ends the part as ``timesteps`` would."""
    if critic_warmup < 0:
        raise ValueError(f"critic_warmup must be >= 0 steps, got {critic_warmup}")
    out = Path(out)
    if resume and not (out / CHECKPOINT).exists():  # before the lock, which makes the directory
        raise CheckpointError(f"--resume: no checkpoint at {out / CHECKPOINT}")
    with held(out):
        return _train(config, out, resume, command, resume_overrides, critic_warmup, freeze_features, callbacks)


def _train(config: TrainConfig, out: Path, resume: bool, command: str, resume_overrides: dict[str, Any] | None,
           critic_warmup: int, freeze_features: bool, callbacks: Sequence[Any]) -> Path:
    """``train`` while holding ``out``'s lock."""
    checkpoint = out / CHECKPOINT
    import torch
    from stable_baselines3 import PPO

    if resume:
        meta, norm = read_bundle_meta(checkpoint)
        if meta.get("kind") != "checkpoint":
            raise CheckpointError(f"{checkpoint} is a {meta.get('kind')} bundle, not a training checkpoint")
        saved = config_from_meta(meta)
        if saved.robot != config.robot:
            raise CheckpointError(f"{checkpoint} trains robot '{saved.robot}', not '{config.robot}'")
        overrides = dict(resume_overrides or {})
        if "envs" in overrides:  # e.g. to play a run on through the acting layers, 64 worlds at most
            overrides["batch_size"] = with_envs(saved, overrides["envs"]).batch_size
        config = replace(saved, timesteps=config.timesteps, workers=config.workers, **overrides)
        state = TrainState.from_dict(meta["state"])
        if "learning_rate" in (resume_overrides or {}):
            state.learning_rate = None
        if "obstacles" in (resume_overrides or {}):  # a new obstacle rule starts its own count
            state.obstacles = ObstacleCurriculum(config.obstacles)
        if config.validate_worlds != saved.validate_worlds:  # scores of other worlds do not compare
            state.best = None
    else:
        if checkpoint.exists():
            raise CheckpointError(f"{checkpoint} exists: pass --resume to continue it, or choose another --out")
        if (out / selection.BEST).exists():
            raise CheckpointError(f"{out / selection.BEST} is left from an earlier run: move it away, or choose "
                                  f"another --out")
        state = TrainState(AugmentedGoalSize(config.goal), ObstacleCurriculum(config.obstacles))
        norm = None

    out.mkdir(parents=True, exist_ok=True)
    venv = build_vec_env(config)
    try:
        tensorboard_dir = str(out / "tensorboard") if _has_tensorboard() else None
        if resume:
            model = PPO.load(str(checkpoint), env=venv, device=config.device, tensorboard_log=tensorboard_dir,
                             batch_size=config.batch_size)  # SB3 sizes the rollout by the new world count itself
            set_learning_rate(model, config.learning_rate)
            set_discount(model, config.gamma)
            if norm is not None:
                restore_normalization(venv, norm)
        else:
            model = build_model(config, venv, tensorboard_dir)
        remaining = config.timesteps - model.num_timesteps
        callback = _make_callback(config, state, out, config.timesteps, critic_warmup, freeze_features)
        if config.imitation_steps and (list(out.glob(DEMOS_GLOB)) or model.num_timesteps >= config.clone_at):
            # before the run's clone there are none yet; after it, or with none planned, they must be there
            callbacks = [imitation_callback(*load_demos(out), steps=config.imitation_steps, seed=config.seed),
                         *callbacks]
        interrupted = False
        if remaining > 0:
            previous = signal.getsignal(signal.SIGTERM)
            signal.signal(signal.SIGTERM, _raise_interrupt)
            threads = torch.get_num_threads()
            try:
                model.learn(remaining, callback=[callback, *callbacks], reset_num_timesteps=False,
                            tb_log_name="ppo", progress_bar=False)
                if config.validate_every and state.best is not None and state.validated_at < model.num_timesteps:
                    callback.validate()  # the last checkpoint is a candidate too
            except KeyboardInterrupt:
                interrupted = True
            finally:
                signal.signal(signal.SIGTERM, previous)
                torch.set_num_threads(threads)  # the callback set them per phase; a next run counts on them
            callback.save_checkpoint()  # the callback is bound to the model only once learn() ran
        if interrupted:
            raise KeyboardInterrupt(f"interrupted at {model.num_timesteps} steps; resume with --resume")
        meta = bundle_meta(config, state, model.num_timesteps, "model", model.observation_space.shape[0])
        meta["command"] = command
        path = save_bundle(model, out / MODEL, meta, model.get_vec_normalize_env())
        plot_curve(out / CURVE, out / CURVE_PNG, title=f"{config.robot.upper()} training",
                   decision_period=config.decision_period)
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


def steps_label(decision_period: int) -> str:
    """What a curve's step axis counts: a run's ``timesteps`` are its policy's decisions."""
    if decision_period == 1:
        return "environment steps"
    return f"decisions (each {decision_period} control steps)"


def plot_curve(csv_path: Path, png_path: Path, title: str, decision_period: int = 1) -> Path | None:
    """The paper's training figure: success rate (and curricula) over the run's timesteps, which
    are decisions of ``decision_period`` control steps each."""
    if not csv_path.exists():
        return None
    from rayreach.env.reach import OUTCOMES

    with csv_path.open() as handle:
        rows = list(csv.DictReader(handle))
    if not rows:
        return None
    steps = np.array([float(r["timesteps"]) for r in rows]) / 1e6
    fig, ax1, ax2 = curve_figure()
    for outcome, color in zip(OUTCOMES, ("#2b9a3e", "#d62728", "#ff7f0e", "#7f7f7f")):
        ax1.plot(steps, [float(r[f"{outcome}_rate"]) for r in rows], color=color, label=outcome.replace("_", " "))
    true_success = [float(r.get("true_success_rate") or "nan") for r in rows]
    if not np.all(np.isnan(true_success)):
        ax1.plot(steps, true_success, color="#2b9a3e", linestyle="--", label="success at the true goal size")
    validation = selection.read_validation(csv_path.parent)
    if validation:
        at = np.array([r["timesteps"] for r in validation]) / 1e6
        ax1.plot(at, [r["success_rate"] for r in validation], "o", color="#2b9a3e", markeredgecolor="black",
                 zorder=5, label=f"success alone, {int(validation[0]['worlds'])} validation worlds")
        ax1.plot(at, [r["collision_rate"] for r in validation], "o", color="#d62728", markeredgecolor="black",
                 zorder=5, label="collisions alone, the same worlds")
        best = max(validation, key=lambda r: r["score"])
        ax1.plot([best["timesteps"] / 1e6], [best["success_rate"]], "*", color="gold", markeredgecolor="black",
                 markersize=16, zorder=6, label="the checkpoint kept (best.zip)")
    ax1.set_ylabel("share of episodes or worlds")
    ax1.set_ylim(-0.02, 1.25)  # room above for the legend
    ax1.set_yticks(np.linspace(0.0, 1.0, 6))
    ax1.legend(loc="upper center", fontsize=7, ncol=3)
    ax1.set_title(title)
    ax1.grid(alpha=0.3)
    ax2.plot(steps, [float(r["goal_size"]) for r in rows], color="#1f5fd6", label="goal size (m)")
    ax2.set_ylabel("goal size (m)")
    ax3 = ax2.twinx()
    ax3.step(steps, [float(r["obstacles"]) for r in rows], color="#8c564b", where="post", label="obstacles")
    ax3.set_ylabel("obstacles")
    return save_curve_figure(fig, ax2, png_path, steps_label(decision_period))


def curve_figure():
    """A training figure's two panels over environment steps: rates above, schedules below."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (upper, lower) = plt.subplots(2, 1, figsize=(8, 6), sharex=True, gridspec_kw={"height_ratios": [2, 1]})
    return fig, upper, lower


def save_curve_figure(fig, lower, png_path: Path, steps_axis: str = steps_label(1)) -> Path:
    """Label the shared step axis, write the figure and free it."""
    import matplotlib.pyplot as plt

    lower.set_xlabel(f"{steps_axis} (millions)")
    lower.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(png_path, dpi=110)
    plt.close(fig)
    return png_path

