"""A policy as one ONNX graph, and acting with it on onnxruntime without torch.

``export_onnx`` writes the deterministic action of ``Policy.act(obs, deterministic=True)``
as a single graph: raw observation in, action out. The frozen observation normalisation
is folded in (in float64, as ``Normalization`` computes it, so the actor sees the same
float32 input), then the actor (feature extractor, policy head, the Gaussian's mean) and
the clip to the action space that stable-baselines3's ``predict`` applies to a Box action.
The bundle's metadata (robot, observation shape and parts, timesteps) travels as the
model's metadata_props, so ``OnnxPolicy`` knows what it drives and what it must be fed.

This module imports torch only inside ``export_onnx``: acting with ``OnnxPolicy`` needs
numpy, onnxruntime and the observation's config, not the training stack.
"""

from __future__ import annotations

import json
import os
import tempfile
import warnings
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from rayreach.learning.bundles import CheckpointError, read_bundle_meta
from rayreach.learning.export import run_bundle

if TYPE_CHECKING:
    from rayreach.env.observation import ObservationConfig

INPUT = "observation"
OUTPUT = "action"
MEAN = "mean"
"""Second output: the Gaussian's mean before the clip, which ``OnnxPolicy.sample`` draws round."""
DEFAULT_OPSET = 17
ONNX_FORMAT = 2
"""Version of the metadata layout below (``rayreach.format``)."""
META_KEYS = ("robot", "kind", "obs_shape", "observation", "timesteps", "action_low", "action_high", "action_std",
             "source", "decision_period")
"""metadata_props written as ``rayreach.<key>``, each a JSON value."""


def export_onnx(policy_or_path: Any, out_path: str | Path, opset: int = DEFAULT_OPSET) -> Path:
    """Write ``policy_or_path`` (a ``Policy``, a bundle or a run directory) to ``out_path`` as
    one ONNX graph ``observation`` (batch x obs_size, float32, the env's raw observation) ->
    ``action`` (batch x 6, float32), the deterministic action, and ``mean``, the same before
    the clip; the Gaussian's standard deviation (state-independent) goes into the metadata.
    Written atomically."""
    import copy

    import onnx
    import torch
    from gymnasium import spaces

    from rayreach.learning.policy import Policy, load_policy

    if isinstance(policy_or_path, Policy):
        policy = policy_or_path
    else:
        policy = load_policy(run_bundle(policy_or_path))
    sb3 = policy.model.policy
    space = policy.model.action_space
    if not isinstance(space, spaces.Box):
        raise CheckpointError(f"{policy.path}: only a Box action space can be exported, not {space}")
    if getattr(sb3, "squash_output", False) or getattr(sb3, "use_sde", False):
        raise CheckpointError(f"{policy.path}: squashed or state-dependent-noise actions are not supported")
    obs_size = int(np.prod(policy.model.observation_space.shape))

    class Actor(torch.nn.Module):
        """Normalise (float64, as numpy does), run the actor, clip to the action space."""

        def __init__(self) -> None:
            super().__init__()
            norm = policy.normalization
            self.normalize = norm is not None
            if norm is not None:
                self.register_buffer("mean", torch.as_tensor(np.asarray(norm.mean, dtype=np.float64)))
                # the same float64 divisor Normalization divides by, so the rounding matches
                self.register_buffer("std", torch.as_tensor(np.sqrt(np.asarray(norm.var, dtype=np.float64)
                                                                    + norm.epsilon)))
                self.clip = float(norm.clip)
            self.features = copy.deepcopy(sb3.pi_features_extractor)
            self.head = copy.deepcopy(sb3.mlp_extractor.policy_net)
            self.mean_net = copy.deepcopy(sb3.action_net)
            self.register_buffer("low", torch.as_tensor(np.asarray(space.low, dtype=np.float32)))
            self.register_buffer("high", torch.as_tensor(np.asarray(space.high, dtype=np.float32)))

        def forward(self, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
            if self.normalize:
                x = (obs.to(torch.float64) - self.mean) / self.std
                obs = torch.clamp(x, -self.clip, self.clip).to(torch.float32)
            mean = self.mean_net(self.head(self.features(obs)))
            return torch.maximum(torch.minimum(mean, self.high), self.low), mean

    actor = Actor().eval()
    out_path = Path(out_path)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=out_path.parent, prefix=".", suffix=".part.onnx")
    os.close(fd)
    try:
        with torch.no_grad(), warnings.catch_warnings():
            # the TorchScript exporter (deprecated, so its warnings are muted): the dynamo one needs
            # onnxscript, and this graph is plain layers
            warnings.simplefilter("ignore", DeprecationWarning)
            torch.onnx.export(actor, (torch.zeros(1, obs_size),), tmp, input_names=[INPUT],
                              output_names=[OUTPUT, MEAN],
                              dynamic_axes={INPUT: {0: "batch"}, OUTPUT: {0: "batch"}, MEAN: {0: "batch"}},
                              opset_version=opset, dynamo=False)
        model = onnx.load(tmp)
        meta = policy.meta
        values = {"robot": policy.robot, "kind": meta.get("kind"), "obs_shape": [obs_size],
                  "observation": meta.get("config", {}).get("observation") or {},
                  "timesteps": meta.get("timesteps"), "action_low": space.low.tolist(),
                  "action_high": space.high.tolist(),
                  "action_std": torch.exp(sb3.log_std.detach()).numpy().astype(float).tolist(),
                  "source": str(policy.path), "decision_period": policy.decision_period}
        del model.metadata_props[:]
        onnx.helper.set_model_props(model, {"rayreach.format": str(ONNX_FORMAT),
                                            **{f"rayreach.{k}": json.dumps(v) for k, v in values.items()}})
        model.doc_string = f"rayreach {policy.robot} policy: raw observation -> deterministic action"
        onnx.checker.check_model(model)
        onnx.save(model, tmp)
        os.replace(tmp, out_path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
    return out_path


class OnnxPolicy:
    """An exported policy on onnxruntime (CPU, one thread: one observation per call, where
    more threads only add overhead). ``act`` gives what ``Policy.act(obs, deterministic=True)``
    gives, for one observation or a batch."""

    def __init__(self, path: str | Path) -> None:
        import onnxruntime as ort

        self.path = Path(path)
        if not self.path.is_file():
            raise CheckpointError(f"no ONNX policy file at {self.path}")
        options = ort.SessionOptions()
        options.intra_op_num_threads = 1
        options.inter_op_num_threads = 1
        try:
            self.session = ort.InferenceSession(str(self.path), options, providers=["CPUExecutionProvider"])
        except Exception as exc:  # onnxruntime raises its own kinds for a damaged or foreign file
            raise CheckpointError(f"{self.path} is not a loadable ONNX model: {exc}") from exc
        props = self.session.get_modelmeta().custom_metadata_map
        if props.get("rayreach.format") != str(ONNX_FORMAT):
            raise CheckpointError(f"{self.path} is not a rayreach ONNX policy of format {ONNX_FORMAT} "
                                  f"(rayreach.format: {props.get('rayreach.format')!r}); export it again")
        self.meta: dict[str, Any] = {k: json.loads(props[f"rayreach.{k}"]) for k in META_KEYS
                                     if f"rayreach.{k}" in props}
        self.obs_size = int(self.meta["obs_shape"][0])

    @property
    def robot(self) -> str:
        return str(self.meta["robot"])

    @property
    def observation(self) -> ObservationConfig:
        """What the policy was trained to see (the paper's 142 values where nothing was saved).
        Imported here: ``rayreach.env`` loads the simulator, which acting on a graph alone needs not."""
        from rayreach.env.observation import ObservationConfig

        return ObservationConfig(**(self.meta.get("observation") or {}))

    @property
    def decision_period(self) -> int:
        """Control steps each action is held for (``rayreach.env.decisions``; 1 where the graph
        predates the choice)."""
        return int(self.meta.get("decision_period", 1))

    def act(self, obs: np.ndarray, deterministic: bool = True) -> np.ndarray:
        """The deterministic action (6,) for one observation, or (batch, 6) for a batch
        (``sample`` draws one)."""
        if not deterministic:
            raise ValueError("act() gives the deterministic action; draw one with OnnxPolicy.sample(obs, rng)")
        obs = np.asarray(obs, dtype=np.float32)
        single = obs.ndim == 1
        batch = obs.reshape(1, -1) if single else obs
        if batch.ndim != 2 or batch.shape[1] != self.obs_size:
            raise ValueError(f"{self.path}: expected observations of {self.obs_size} values, "
                             f"got shape {obs.shape}")
        action = self.session.run([OUTPUT], {INPUT: batch})[0]
        return action[0] if single else action

    def sample(self, obs: np.ndarray, rng: np.random.Generator, least_std: float = 0.0) -> np.ndarray:
        """An action drawn from the policy's Gaussian with ``rng``, clipped to the action
        space, as ``Policy.sample`` draws it (``ActingPolicy`` draws where the arm was held),
        each dimension's standard deviation at least ``least_std``."""
        obs = np.asarray(obs, dtype=np.float32).reshape(1, -1)
        if obs.shape[1] != self.obs_size:
            raise ValueError(f"{self.path}: expected observations of {self.obs_size} values, got {obs.shape[1]}")
        mean = self.session.run([MEAN], {INPUT: obs})[0][0]
        std = np.maximum(np.asarray(self.meta["action_std"], dtype=np.float32), np.float32(least_std))
        low, high = (np.asarray(self.meta[k], dtype=np.float32) for k in ("action_low", "action_high"))
        return np.clip(mean + std * rng.standard_normal(mean.shape), low, high).astype(np.float32)
