"""An exported ONNX graph acts as the torch policy does, on observations from real episodes."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("onnxruntime")
pytest.importorskip("onnx")

from rayreach.cli import main  # noqa: E402
from rayreach.env.observation import ObservationConfig  # noqa: E402
from rayreach.env.reach import ReachEnv  # noqa: E402
from rayreach.learning.bundles import CheckpointError, save_bundle  # noqa: E402
from rayreach.learning.onnx_export import OnnxPolicy, export_onnx  # noqa: E402
from rayreach.learning.policy import load_policy  # noqa: E402
from rayreach.planners.drl import MODELS_DIR  # noqa: E402

TOLERANCE = 1e-5
"""Max abs difference allowed between onnxruntime's and torch's action."""


def _observations(policy, envs, n, seed=0, max_steps=150):
    """``n`` observations from episodes of ``policy`` in ``envs`` (in turn), with its sampled
    actions: a stochastic policy visits more states than its deterministic path."""
    rng = np.random.default_rng(seed)
    out, episode = [], 0
    while len(out) < n:
        env = envs[episode % len(envs)]
        obs, _ = env.reset(seed=seed + episode)
        for _ in range(max_steps):
            out.append(obs)
            obs, _, terminated, truncated, _ = env.step(policy.sample(obs, rng))
            if terminated or truncated or len(out) >= n:
                break
        episode += 1
    return np.asarray(out, dtype=np.float32)


def _planner_bundle(path):
    """A fresh PPO on the 577-value planner observation with the project's network, its
    action head scaled so that actions leave [-1, 1] (the clip is exercised), and a frozen
    normalisation with uneven mean and variance (some values clipped at +-5)."""
    import torch
    from stable_baselines3 import PPO

    from rayreach.networks import SharedMLP

    config = ObservationConfig.planner()
    env = ReachEnv(robot="ur5", observation=config)
    model = PPO("MlpPolicy", env, n_steps=64, batch_size=64, seed=3, device="cpu",
                policy_kwargs={"features_extractor_class": SharedMLP, "features_extractor_kwargs": {"layers": (64, 64)},
                               "net_arch": {"pi": [32], "vf": [32]}})
    with torch.no_grad():
        model.policy.action_net.weight.mul_(300.0)
    size = env.observation_space.shape[0]
    rng = np.random.default_rng(7)
    arrays = {"obs_mean": rng.uniform(-0.5, 0.5, size), "obs_var": rng.uniform(1e-4, 2.0, size),
              "obs_count": np.array(1e4), "ret_mean": np.array(0.0), "ret_var": np.array(1.0),
              "ret_count": np.array(1.0), "clip_obs": np.array(5.0), "clip_reward": np.array(10.0),
              "epsilon": np.array(1e-8), "norm_obs": np.array(True), "norm_reward": np.array(True)}
    meta = {"kind": "checkpoint", "robot": "ur5", "obs_shape": [size], "timesteps": 0,
            "config": {"robot": "ur5", "observation": dataclasses.asdict(config)}}
    save_bundle(model, path, meta, arrays)
    env.close()
    return path


@pytest.fixture(scope="module")
def cases(tmp_path_factory):
    """Per policy: (torch Policy, exported OnnxPolicy, observations from its episodes)."""
    folder = tmp_path_factory.mktemp("onnx")
    made = {}
    ur5 = load_policy(MODELS_DIR / "ur5.zip")
    envs = [ReachEnv(robot="ur5"), ReachEnv(robot="ur5", scenario="exp1")]
    made["ur5"] = (ur5, OnnxPolicy(export_onnx(ur5, folder / "ur5.onnx")), _observations(ur5, envs, 1000))
    kr16 = load_policy(MODELS_DIR / "kr16.zip")
    envs += [ReachEnv(robot="kr16", observation=kr16.observation), ReachEnv(scenario="exp4", observation=kr16.observation)]
    made["kr16"] = (kr16, OnnxPolicy(export_onnx(MODELS_DIR / "kr16.zip", folder / "kr16.onnx")),
                    _observations(kr16, envs[2:], 300, seed=100))
    planner = load_policy(_planner_bundle(folder / "planner.zip"))
    envs.append(ReachEnv(robot="ur5", observation=planner.observation))
    made["planner"] = (planner, OnnxPolicy(export_onnx(folder / "planner.zip", folder / "planner.onnx")),
                       _observations(planner, envs[-1:], 300, seed=200))
    yield made
    for env in envs:
        env.close()


@pytest.mark.parametrize("name", ["ur5", "kr16", "planner"])
def test_onnx_action_equals_torch_action(cases, name):
    policy, graph, obs = cases[name]
    assert obs.shape[1] == policy.model.observation_space.shape[0] == graph.obs_size
    torch_actions = np.stack([policy.act(o, deterministic=True) for o in obs])  # as the planners call it
    batch = graph.act(obs)
    single = np.stack([graph.act(o) for o in obs[:100]])
    assert batch.shape == (len(obs), 6) and batch.dtype == np.float32 and single.shape == (100, 6)
    difference = np.abs(batch - torch_actions).max()
    print(f"{name}: max |onnxruntime - torch| = {difference:.1e} over {len(obs)} observations")  # shown with -s
    assert difference <= TOLERANCE
    assert np.abs(single - torch_actions[:100]).max() <= TOLERANCE
    assert np.all(np.abs(batch) <= 1.0)
    # the comparison can tell: the actor on unnormalised observations acts otherwise
    raw, _ = policy.model.predict(obs, deterministic=True)
    assert np.abs(raw - torch_actions).max() > 100 * TOLERANCE


def test_planner_graph_folds_clipping_and_its_metadata(cases):
    policy, graph, obs = cases["planner"]
    assert obs.shape[1] == 577 and graph.robot == "ur5" and graph.observation == ObservationConfig.planner()
    assert graph.meta["timesteps"] == 0 and graph.meta["obs_shape"] == [577]
    normalized = (obs - policy.normalization.mean) / np.sqrt(policy.normalization.var + 1e-8)
    assert np.abs(normalized).max() > 5.0  # the normalisation's clip was needed
    actions = graph.act(obs)
    assert np.mean(np.abs(actions) == 1.0) > 0.05  # and the action space's clip
    ur5 = cases["ur5"][1]
    assert ur5.robot == "ur5" and ur5.observation == ObservationConfig() and ur5.meta["obs_shape"] == [142]
    assert cases["kr16"][1].robot == "kr16"


@pytest.mark.parametrize("name", ["ur5", "planner"])
def test_onnx_sample_draws_as_torch_does(cases, name):
    """Where the arm was held, the planner draws from the policy's Gaussian: the graph's mean
    before the clip and the standard deviation in its metadata give torch's draw."""
    policy, graph, obs = cases[name]
    for i, o in enumerate(obs[:50]):
        ours = graph.sample(o, np.random.default_rng(i))
        assert np.abs(ours - policy.sample(o, np.random.default_rng(i))).max() <= TOLERANCE
    assert not np.allclose(graph.sample(obs[0], np.random.default_rng(0)), graph.act(obs[0]))


def test_onnx_policy_acts_without_torch(cases, tmp_path):
    policy, graph, obs = cases["planner"]
    np.save(tmp_path / "obs.npy", obs[:50])
    code = f"""
import sys
sys.modules["torch"] = None  # any import of torch now fails
import numpy as np
from rayreach.learning.onnx_export import OnnxPolicy
policy = OnnxPolicy({str(graph.path)!r})
np.save({str(tmp_path / "act.npy")!r}, policy.act(np.load({str(tmp_path / "obs.npy")!r})))
print(policy.robot, policy.observation.scans, "stable_baselines3" in sys.modules)
"""
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split()[-3:] == ["ur5", "3", "False"]
    assert np.array_equal(np.load(tmp_path / "act.npy"), graph.act(obs[:50]))


def test_cli_export_writes_a_graph_that_loads(cases, tmp_path, capsys):
    assert main(["export", "--model", "kr16", "--onnx", str(tmp_path / "kr16.onnx")]) == 0
    assert f"wrote {tmp_path / 'kr16.onnx'}" in capsys.readouterr().out
    policy, _, obs = cases["kr16"]
    graph = OnnxPolicy(tmp_path / "kr16.onnx")
    assert graph.robot == "kr16" and np.abs(graph.act(obs[:20]) - policy.act(obs[:20])).max() <= TOLERANCE
    # a run directory's bundle, copied with --to and exported from the copy
    run = tmp_path / "run"
    run.mkdir()
    (run / "checkpoint.zip").write_bytes((MODELS_DIR / "ur5.zip").read_bytes())
    assert main(["export", "--run", str(run), "--to", str(tmp_path / "ur5.zip"), "--onnx",
                 str(tmp_path / "ur5.onnx")]) == 0
    out = capsys.readouterr().out
    assert all(f"wrote {tmp_path / name}" in out for name in ("ur5.zip", "ur5.json", "ur5.onnx"))
    assert json.loads((tmp_path / "ur5.json").read_text())["robot"] == "ur5"
    assert OnnxPolicy(tmp_path / "ur5.onnx").meta["source"] == str(tmp_path / "ur5.zip")


def test_bad_paths_give_clear_errors(cases, tmp_path, capsys):
    with pytest.raises(CheckpointError, match="no model file"):
        export_onnx(tmp_path / "missing.zip", tmp_path / "x.onnx")
    assert not (tmp_path / "x.onnx").exists()
    with pytest.raises(CheckpointError, match="no ONNX policy file"):
        OnnxPolicy(tmp_path / "missing.onnx")
    (tmp_path / "junk.onnx").write_text("not a graph")
    with pytest.raises(CheckpointError, match="not a loadable ONNX model"):
        OnnxPolicy(tmp_path / "junk.onnx")
    with pytest.raises(ValueError, match="expected observations of 142 values"):
        cases["ur5"][1].act(np.zeros(553, dtype=np.float32))
    assert main(["export", "--model", "ur7", "--onnx", str(tmp_path / "y.onnx")]) == 2
    assert "no shipped policy for 'ur7'" in capsys.readouterr().err
    assert main(["export", "--model", str(tmp_path / "missing.zip"), "--onnx", str(tmp_path / "y.onnx")]) == 2
    assert "no model file" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["export", "--model", "ur5"])  # neither --to nor --onnx
    assert not list(tmp_path.glob("*.part.onnx")) and not (tmp_path / "y.onnx").exists()
