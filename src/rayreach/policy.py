"""Saved policies: one zip holds the PPO model, its observation normalisation and metadata.

The file is stable-baselines3's own zip with two more entries, ``rayreach/meta.json`` and
``rayreach/normalization.npz``, so evaluation always sees the statistics training saw, frozen.
Checkpoints use the same format and also carry the optimiser, the reward normalisation and
the curricula, so training resumes where it stopped.
"""

from __future__ import annotations

import io
import json
import math
import os
import tempfile
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar, Sequence

import numpy as np

from rayreach.transforms import rotvec_to_matrix

META_ENTRY = "rayreach/meta.json"
NORM_ENTRY = "rayreach/normalization.npz"
FORMAT = 1


class CheckpointError(ValueError):
    """A model or checkpoint file that cannot be used; the message says why."""


@dataclass
class Normalization:
    """Frozen observation normalisation: (obs - mean) / sqrt(var + eps), clipped."""

    mean: np.ndarray
    var: np.ndarray
    clip: float
    epsilon: float

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        out = (np.asarray(obs, dtype=np.float64) - self.mean) / np.sqrt(self.var + self.epsilon)
        return np.clip(out, -self.clip, self.clip).astype(np.float32)

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray] | None) -> "Normalization | None":
        """The frozen observation normalisation of a bundle's arrays; None if it has none."""
        if arrays is None or not bool(arrays["norm_obs"]):
            return None
        return cls(arrays["obs_mean"], arrays["obs_var"], float(arrays["clip_obs"]), float(arrays["epsilon"]))


def normalization_arrays(vecnorm: Any) -> dict[str, np.ndarray]:
    """Everything a VecNormalize needs to continue, as arrays."""
    return {
        "obs_mean": vecnorm.obs_rms.mean,
        "obs_var": vecnorm.obs_rms.var,
        "obs_count": np.array(vecnorm.obs_rms.count),
        "ret_mean": np.array(vecnorm.ret_rms.mean),
        "ret_var": np.array(vecnorm.ret_rms.var),
        "ret_count": np.array(vecnorm.ret_rms.count),
        "clip_obs": np.array(vecnorm.clip_obs),
        "clip_reward": np.array(vecnorm.clip_reward),
        "epsilon": np.array(vecnorm.epsilon),
        "norm_obs": np.array(vecnorm.norm_obs),
        "norm_reward": np.array(vecnorm.norm_reward),
    }


def restore_normalization(vecnorm: Any, arrays: dict[str, np.ndarray]) -> None:
    vecnorm.obs_rms.mean = arrays["obs_mean"].copy()
    vecnorm.obs_rms.var = arrays["obs_var"].copy()
    vecnorm.obs_rms.count = float(arrays["obs_count"])
    vecnorm.ret_rms.mean = float(arrays["ret_mean"])
    vecnorm.ret_rms.var = float(arrays["ret_var"])
    vecnorm.ret_rms.count = float(arrays["ret_count"])


def save_bundle(model: Any, path: str | Path, meta: dict[str, Any], vecnorm: Any | dict[str, np.ndarray] | None) -> Path:
    """Write model + metadata + normalisation atomically (a crash never leaves half a file).
    ``vecnorm``: a VecNormalize, or the arrays ``read_bundle_meta`` returned for one."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".", suffix=".part.zip")
    os.close(fd)
    try:
        model.save(tmp)
        with zipfile.ZipFile(tmp, "a") as archive:
            archive.writestr(META_ENTRY, json.dumps({"format": FORMAT, **meta}, indent=2, default=_json_default))
            if vecnorm is not None:
                buffer = io.BytesIO()
                np.savez(buffer, **(vecnorm if isinstance(vecnorm, dict) else normalization_arrays(vecnorm)))
                archive.writestr(NORM_ENTRY, buffer.getvalue())
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
    return path


def _json_default(value: Any) -> Any:
    if isinstance(value, (np.integer, np.floating)):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    return str(value)


def read_bundle_meta(path: str | Path) -> tuple[dict[str, Any], dict[str, np.ndarray] | None]:
    """Metadata and normalisation arrays of a bundle; a clear error for anything else."""
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"no model file at {path}")
    try:
        with zipfile.ZipFile(path) as archive:
            names = set(archive.namelist())
            if META_ENTRY not in names or "policy.pth" not in names:
                raise CheckpointError(
                    f"{path} is not a rayreach model or checkpoint (missing {META_ENTRY} or policy.pth)"
                )
            meta = json.loads(archive.read(META_ENTRY))
            norm = None
            if NORM_ENTRY in names:
                with np.load(io.BytesIO(archive.read(NORM_ENTRY))) as data:
                    norm = {k: data[k] for k in data.files}
    except (zipfile.BadZipFile, json.JSONDecodeError, OSError, ValueError, KeyError) as exc:
        if isinstance(exc, CheckpointError):
            raise
        raise CheckpointError(f"{path} is corrupt or truncated: {exc}") from exc
    if meta.get("format") != FORMAT:
        raise CheckpointError(f"{path} has format {meta.get('format')!r}; this rayreach reads format {FORMAT}")
    return meta, norm


@dataclass(frozen=True)
class FinalApproach:
    """Step straight at the goal once the policy has brought the end effector within
    ``radius`` and everything the rays see lies at least ``margin`` from the tool on that
    straight path.

    Not in the paper. The mean action of a PPO policy trained with an enlarged goal tends to
    settle a few centimetres from the goal (the sampling noise did the last centimetres in
    training), so a deterministic rollout times out beside a goal it has reached in all but
    name (docs/training.md, "Acting"). The environment applies it
    (``EnvConfig.final_approach``), where the rays' hit points are known, and sets the
    robot's step and tool (and radii, unless given). The straight path is ``radius`` long at
    most (``axial_radius`` along the tool's axis). Where only the tool's back blocks it, the
    tool first turns about its tip towards the path (``turn``). From farther away it can
    nudge a policy that has stalled towards the goal (``stall_steps``, off by default)."""

    NEARER: ClassVar[float] = 0.001
    """How much nearer, m, the path may bring the tool to what it sees than the nearest hit
    is now, once that is within the margin (rounding, not a distance that matters)."""
    TURNED: ClassVar[float] = 1e-3
    """Angle, rad, between the tool and its path under which the tool counts as pointing
    along it (``turn``)."""

    radius: float | None = None
    """None: the robot's (``RobotSpec.final_approach_radius``), which the environment fills
    in. The UR5's is the enlarged goal the curriculum trains at (0.1 m), which the policy
    reliably comes this close to; from 0.13 m on, its straight paths ran under moving goal
    covers whose thin edges no ray saw, and the tool met them. The KR16's is 0.2 m, where it
    met nothing more."""
    axial_radius: float | None = None
    """None: the robot's (``RobotSpec.final_approach_axial_radius``). From within this
    distance too, m, but only where the path lies within ``axial_angle`` of the tool's axis:
    a tool moving along its own axis sweeps little more than the cone its tip rays look
    into. The UR5's policy descends onto a goal below it, as in exp1, from 0.12 m; a radius
    of 0.13 m in every direction drove its tool under moving goal covers. At or below
    ``radius`` it changes nothing."""
    axial_angle: float = math.radians(15.0)
    """Largest angle, rad, between the tool's axis and the path for ``axial_radius``."""
    margin: float = 0.01
    """Least clearance, m, between the tool's surface on the straight path and anything a ray
    sees. Testing the path rather than every ray lets the tool pass beside a wall next to
    the goal."""
    ee_step: float = 0.005
    """The robot's largest translation per action, m."""
    rot_step: float = 0.005
    """The robot's largest rotation per action, rad."""
    tool_length: float = 0.0
    """Length of the cylindrical tool behind the end effector, m (0: the tip alone)."""
    tool_radius: float = 0.0
    """Radius of that tool, m."""
    stall_steps: int = 0
    """When the last this many steps brought the end effector less than ``stall_gain``
    nearer the goal, step towards it instead of the policy (through the safety layer), from
    any distance, until they have: a nudge of about ``stall_gain``, after which the policy
    acts again from a new state. The mean action of a policy that hovers or presses against
    what it sees repeats itself until the step budget runs out. 0 (the default): off. At 100
    the shipped policies succeed more often and collide more often too, since the nudges go
    where no ray looks (docs/training.md, "Acting"), so it is the user's choice."""
    stall_gain: float = 0.01
    """Least progress towards the goal, m, over ``stall_steps`` steps."""
    turn: bool = True
    """Where the tip's own path (the tool's radius around it) keeps the margin and only the
    tool behind it does not, turn the tool about its tip, one rotation step at a time,
    towards the path, while the turned tool keeps the margin or comes no nearer to anything
    seen. A tool pointing along its path sweeps only the path. A KR16 tool tilted across an
    upright plate beside the goal swept its back over the plate's edge, so the path was
    refused again and again and the run timed out (docs/training.md, "Acting")."""

    def __post_init__(self) -> None:
        for name in ("radius", "axial_radius", "axial_angle", "ee_step", "rot_step", "stall_gain"):
            if getattr(self, name) is not None and not getattr(self, name) > 0:
                raise ValueError(f"{name} must be positive, got {getattr(self, name)}")
        for name in ("margin", "tool_length", "tool_radius", "stall_steps"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)}")
        if not isinstance(self.stall_steps, (int, np.integer)):
            raise ValueError(f"stall_steps must be a whole number of steps, got {self.stall_steps}")

    def stalled(self, distances: Sequence[float]) -> bool:
        """Whether ``distances`` (to the current goal after each step, oldest first) show a
        stall: ``stall_steps`` steps that brought the end effector less than ``stall_gain``
        nearer."""
        return self.stall_steps > 0 and stalled(distances, self.stall_steps, self.stall_gain)

    @staticmethod
    def towards(goal_offset: np.ndarray) -> np.ndarray:
        """A full step along ``goal_offset`` (goal minus end effector, m), as an action (also the
        safety layer's slide, ``ReachEnv.step``)."""
        action = np.zeros(6, dtype=np.float32)
        action[:3] = np.asarray(goal_offset, dtype=float) / max(float(np.linalg.norm(goal_offset)), 1e-9)
        return action

    def action(self, goal_offset: np.ndarray, hits: np.ndarray,
               tool_direction: np.ndarray | None = None) -> np.ndarray | None:
        """The straight step along ``goal_offset`` (goal minus end effector, m), or None to
        leave it to the policy. ``hits``: the points the rays see, relative to the end
        effector, shape (n, 3). ``tool_direction``: unit vector from the flange to the tip
        (None: the tip alone, with ``tool_radius`` around it); the tool's axis sweeps a
        parallelogram along the path, which every hit must clear by ``tool_radius + margin``,
        unless one hit is that near already and the path brings the tool no nearer to any
        hit than to that one now (a wall it slides along, a compartment it reaches into).
        A hit within ``NEARER`` of the tool (contact) therefore no longer blocks the path;
        the safety layer's ray shield still does. Where the path is refused, the step may be
        a turn of the tool instead (``turn``): a rotation and no translation."""
        if self.radius is None:
            raise ValueError("FinalApproach.radius is None: give one, or let ReachEnv fill in the robot's")
        goal_offset = np.asarray(goal_offset, dtype=float)
        if not self.within_reach(goal_offset, tool_direction):
            return None
        if len(hits):
            hits = np.asarray(hits, dtype=float)
            back = np.zeros(3) if tool_direction is None else -self.tool_length * np.asarray(tool_direction, float)
            on_path = distances_to_parallelogram(hits, goal_offset, back).min()
            if on_path < self.tool_radius + self.margin:
                now = distances_to_segment(hits, np.zeros(3), back).min()  # the tool where it is
                if on_path < now - self.NEARER:
                    return self._turn(goal_offset, hits, tool_direction, now) if self.turn else None
        # along the path tested, not clipped axis by axis: a goal 10 cm below and 1 cm aside
        # took steps of 5 mm down and 5 mm aside, towards a wall beside the goal
        action = np.zeros(6, dtype=np.float32)
        action[:3] = goal_offset / max(float(np.abs(goal_offset).max()), self.ee_step)
        return action

    def within_reach(self, goal_offset: np.ndarray, tool_direction: np.ndarray | None = None) -> bool:
        """Whether the goal, ``goal_offset`` (m) from the end effector, is near enough to step
        straight at: within ``radius``, or within ``axial_radius`` along the tool's axis."""
        distance = float(np.linalg.norm(goal_offset))
        if distance < self.radius:  # type: ignore[operator]
            return True
        if self.axial_radius is None or tool_direction is None or distance >= self.axial_radius:
            return False
        along = float(np.asarray(goal_offset, float) @ np.asarray(tool_direction, float))
        return along > distance * math.cos(self.axial_angle)

    def _turn(self, goal_offset: np.ndarray, hits: np.ndarray, tool_direction: np.ndarray | None,
              now: float) -> np.ndarray | None:
        """One rotation step of the tool about its tip towards ``goal_offset``, as an action;
        None where the tip's own path is refused too, the tool points along the path
        already, or the turned tool would come within the margin of a hit and nearer to it
        than the tool is now to any (``now``)."""
        length = float(np.linalg.norm(goal_offset))
        if tool_direction is None or not length > 0:
            return None
        need = self.tool_radius + self.margin
        if distances_to_segment(hits, np.zeros(3), goal_offset).min() < need:
            return None
        tool, path = np.asarray(tool_direction, dtype=float), goal_offset / length
        axis = np.cross(tool, path)
        size = float(np.linalg.norm(axis))
        angle = float(np.arctan2(size, tool @ path))
        if angle < self.TURNED or size < 1e-12:
            return None
        rotation = axis / size * min(angle, self.rot_step)
        turned = rotvec_to_matrix(rotation) @ tool
        after = distances_to_segment(hits, np.zeros(3), -self.tool_length * turned).min()
        if after < need and after < now:  # no allowance: turn after turn would creep nearer
            return None
        action = np.zeros(6, dtype=np.float32)
        action[3:] = rotation / self.rot_step
        return action


def stalled(distances: Sequence[float], steps: int, gain: float) -> bool:
    """Whether ``distances`` (to the current goal after each step, oldest first) hold ``steps``
    steps (>= 1) and the last ``steps`` of them brought the end effector less than ``gain``
    nearer."""
    return len(distances) > steps and distances[-steps - 1] - distances[-1] < gain


def distances_to_segment(points: np.ndarray, a: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Distance of each point (n, 3) to the segment from ``a`` to ``a + d`` (a point if d = 0)."""
    rel = points - a
    t = np.clip((rel @ d) / (d @ d), 0.0, 1.0) if d @ d > 0 else np.zeros(len(points))
    return np.linalg.norm(rel - t[:, None] * d, axis=1)


def distances_to_parallelogram(points: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Distance of each point (n, 3) to the parallelogram {s u + t v : s, t in [0, 1]}; a
    zero or degenerate side makes it a segment or a point."""
    zero = np.zeros(3)
    best = np.minimum.reduce([distances_to_segment(points, a, d) for a, d in ((zero, u), (v, u), (zero, v), (u, v))])
    gram = np.array([[u @ u, u @ v], [u @ v, v @ v]])
    if np.linalg.det(gram) > 1e-12 * max(gram[0, 0] * gram[1, 1], 1e-30):
        st = np.linalg.solve(gram, np.stack([points @ u, points @ v]))
        inside = np.all((st >= 0.0) & (st <= 1.0), axis=0)
        if inside.any():
            foot = st[0, inside, None] * u + st[1, inside, None] * v
            best[inside] = np.linalg.norm(points[inside] - foot, axis=1)
    return best


@dataclass
class Policy:
    """A loaded policy: ``act(obs)`` normalises with the frozen statistics and runs the actor."""

    model: Any
    normalization: Normalization | None
    meta: dict[str, Any]
    path: Path

    @property
    def robot(self) -> str:
        return str(self.meta["robot"])

    def act(self, obs: np.ndarray, deterministic: bool = True) -> np.ndarray:
        action, _ = self.model.predict(self._normalized(obs), deterministic=deterministic)
        return action

    def sample(self, obs: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """An action drawn from the policy's Gaussian with ``rng`` (not torch's global
        generator, so that a seeded run repeats), clipped to the action space as
        ``act`` clips."""
        import torch

        with torch.no_grad():
            tensor, _ = self.model.policy.obs_to_tensor(self._normalized(obs))
            gaussian = self.model.policy.get_distribution(tensor).distribution
            mean, std = gaussian.mean.numpy()[0], gaussian.stddev.numpy()[0]
        space = self.model.action_space
        return np.clip(mean + std * rng.standard_normal(mean.shape), space.low, space.high).astype(np.float32)

    def _normalized(self, obs: np.ndarray) -> np.ndarray:
        return self.normalization(obs) if self.normalization is not None else obs


class ActingPolicy:
    """The policy as the planner acts with it: its mean action, except on an observation it
    has just acted on, where it draws one from its own distribution (``deterministic``
    False: every action drawn, as SB3 draws them).

    The observation repeats when the arm held still (the arm's rule refused the step and
    every shorter share of it) and nothing in view moved. The mean action would then repeat
    too, and the arm stay held until the step budget ran out: 17 of the KR16's 65 failures
    in 800 random worlds (docs/training.md, "Acting"). A drawn action goes through the same
    layers as any other. ``reset(seed)`` starts each run, so a seeded run repeats."""

    def __init__(self, policy: Policy, deterministic: bool = True, resample: bool = True) -> None:
        self.policy = policy
        self.deterministic = deterministic
        self.resample = resample
        self._rng = np.random.default_rng(0)
        self._last: np.ndarray | None = None

    @property
    def draws_where_held(self) -> bool:
        """Whether a repeated observation draws its action (the mean is acted on otherwise)."""
        return self.deterministic and self.resample

    def reset(self, seed: int) -> None:
        self._rng = np.random.default_rng(seed)
        self._last = None

    def act(self, obs: np.ndarray) -> np.ndarray:
        if not self.deterministic:
            return self.policy.act(obs, deterministic=False)
        repeated = self._last is not None and np.array_equal(obs, self._last)
        self._last = np.array(obs, copy=True)
        if self.resample and repeated:
            return self.policy.sample(obs, self._rng)
        return self.policy.act(obs, deterministic=True)


def load_policy(path: str | Path, device: str = "cpu") -> Policy:
    """Load a model or checkpoint bundle for acting (normalisation frozen).

    Sets torch to one thread: acting runs one observation per call, where intra-op threads
    only add overhead and spin against an evaluation's other workers or a training run
    (exp3 DRL runs took 1.4 to 9.8 s with two threads per worker, 0.25 s with one)."""
    import torch
    from stable_baselines3 import PPO

    torch.set_num_threads(1)
    meta, norm = read_bundle_meta(path)
    try:
        model = PPO.load(str(path), device=device)
    except Exception as exc:  # SB3 raises many kinds on a damaged zip
        raise CheckpointError(f"{path}: the PPO model inside cannot be loaded: {exc}") from exc
    obs_size = model.observation_space.shape
    if tuple(obs_size) != tuple(meta.get("obs_shape", obs_size)):
        raise CheckpointError(f"{path}: observation shape {obs_size} does not match its metadata")
    return Policy(model, Normalization.from_arrays(norm), meta, Path(path))


def train_command(config: dict, out: str | Path) -> str:
    """The ``rayreach train`` command line a run's saved configuration stands for, with the
    flags that stay on through ``--resume`` (acting layers, a fixed obstacle count); flags
    given to one part only (``--freeze-features``, ``--critic-warmup``) are not saved."""
    command = (f"rayreach train --robot {config['robot']} --timesteps {config['timesteps']} --envs {config['envs']} "
               f"--out {out} --checkpoint-every {config['checkpoint_every']}")
    if config.get("acting_layers"):
        command += " --acting-layers"
    obstacles = config.get("obstacles", {})
    if obstacles and obstacles["minimum"] == obstacles["maximum"] == obstacles["start"]:
        command += f" --obstacles {obstacles['start']}"
    return command + " [--resume]"


def export_bundle(source: str | Path, target: str | Path) -> tuple[Path, Path]:
    """Copy a run's model (or its latest checkpoint) to ``target`` and write the metadata
    beside it as ``target`` with a .json suffix: what a shipped policy carries."""
    import shutil

    source, target = Path(source), Path(target)
    if source.is_dir():
        candidates = [source / "model.zip", source / "checkpoint.zip"]
        found = [c for c in candidates if c.exists()]
        if not found:
            raise CheckpointError(f"{source} holds neither model.zip nor checkpoint.zip")
        source = max(found, key=lambda c: read_bundle_meta(c)[0]["timesteps"])
    meta, _ = read_bundle_meta(source)
    target.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(source, target)
    info = {k: meta.get(k) for k in ("robot", "kind", "timesteps", "wall_time_s", "machine", "git_commit", "command")}
    if not info["command"]:  # checkpoints do not record the command line; this reproduces the run
        info["command"] = train_command(meta["config"], source.parent)
    info["source"] = str(source)
    info["curriculum"] = {"goal_size": meta["state"]["goal"]["size"], "obstacles": meta["state"]["obstacles"]["count"],
                          "episodes": meta["state"]["episodes"]}
    info["config"] = meta["config"]
    # demonstrations cloned into the checkpoint (rayreach.demonstrations) leave their reports beside it
    info["demonstrations"] = [json.loads(r.read_text()) for r in sorted(source.parent.glob("clone-*.json"))]
    json_path = target.with_suffix(".json")
    json_path.write_text(json.dumps(info, indent=2, default=_json_default) + "\n")
    return target, json_path
