"""Many environments in few processes: one message per process per step.

SB3's ``SubprocVecEnv`` runs one environment per process and pays a pipe round trip per
environment and step, which on this project's 2-core machine cost as much as the
environment itself. ``WorkerVecEnv`` gives each worker process a slice of the environments,
steps them one after the other and sends all their results back in one message.
"""

from __future__ import annotations

import multiprocessing as mp
from typing import Any, Callable, Sequence

import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env.base_vec_env import CloudpickleWrapper, VecEnv, VecEnvIndices


def _worker(remote, parent_remote, fns_wrapper: CloudpickleWrapper) -> None:
    parent_remote.close()
    envs = [fn() for fn in fns_wrapper.var]
    try:
        while True:
            cmd, data = remote.recv()
            if cmd == "step":
                results = []
                for env, action in zip(envs, data):
                    obs, reward, terminated, truncated, info = env.step(action)
                    done = terminated or truncated
                    info["TimeLimit.truncated"] = truncated and not terminated
                    if done:
                        info["terminal_observation"] = obs
                        obs, reset_info = env.reset()
                        info["reset_info"] = reset_info
                    results.append((obs, reward, done, info))
                obs, rewards, dones, infos = zip(*results)
                remote.send((np.stack(obs), np.array(rewards, dtype=np.float32), np.array(dones), list(infos)))
            elif cmd == "reset":
                seeds, options = data
                out = [env.reset(seed=s, options=o) for env, s, o in zip(envs, seeds, options)]
                remote.send((np.stack([o for o, _ in out]), [i for _, i in out]))
            elif cmd == "get_attr":
                indices, name = data
                remote.send([envs[i].get_wrapper_attr(name) for i in indices])
            elif cmd == "set_attr":
                indices, name, value = data
                remote.send([envs[i].set_wrapper_attr(name, value) for i in indices])
            elif cmd == "env_method":
                indices, name, args, kwargs = data
                remote.send([envs[i].get_wrapper_attr(name)(*args, **kwargs) for i in indices])
            elif cmd == "is_wrapped":
                indices, wrapper = data
                from stable_baselines3.common.env_util import is_wrapped

                remote.send([is_wrapped(envs[i], wrapper) for i in indices])
            elif cmd == "spaces":
                remote.send((envs[0].observation_space, envs[0].action_space))
            elif cmd == "close":
                break
    except KeyboardInterrupt:
        pass  # the parent handles Ctrl-C; a worker just stops
    finally:
        for env in envs:
            env.close()
        remote.close()


class WorkerVecEnv(VecEnv):
    """``len(env_fns)`` environments split as evenly as possible over ``n_workers`` processes."""

    def __init__(self, env_fns: Sequence[Callable[[], gym.Env]], n_workers: int, start_method: str | None = None):
        n_envs = len(env_fns)
        n_workers = max(1, min(n_workers, n_envs))
        bounds = np.linspace(0, n_envs, n_workers + 1).astype(int)
        self._slices = [slice(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:])]
        ctx = mp.get_context(start_method or ("forkserver" if "forkserver" in mp.get_all_start_methods() else "spawn"))
        self.remotes, self.processes = [], []
        for part in self._slices:
            remote, work_remote = ctx.Pipe()
            process = ctx.Process(
                target=_worker, args=(work_remote, remote, CloudpickleWrapper(list(env_fns[part]))), daemon=True
            )
            process.start()
            work_remote.close()
            self.remotes.append(remote)
            self.processes.append(process)
        self.remotes[0].send(("spaces", None))
        observation_space, action_space = self.remotes[0].recv()
        self.closed = False
        self._pending: list = []
        """Remotes whose reply to the last step has not been read yet."""
        super().__init__(n_envs, observation_space, action_space)

    # ------------------------------------------------------------------ stepping
    def step_async(self, actions: np.ndarray) -> None:
        for remote, part in zip(self.remotes, self._slices):
            remote.send(("step", actions[part]))
        self._pending = list(self.remotes)

    def step_wait(self):
        results = []
        for remote in self.remotes:
            results.append(remote.recv())
            self._pending.remove(remote)  # a Ctrl-C between two replies must not leave close() waiting
        obs = np.concatenate([r[0] for r in results])
        rewards = np.concatenate([r[1] for r in results])
        dones = np.concatenate([r[2] for r in results])
        infos = [info for r in results for info in r[3]]
        return obs, rewards, dones, infos

    def reset(self):
        for remote, part in zip(self.remotes, self._slices):
            remote.send(("reset", (self._seeds[part], self._options[part])))
        results = [remote.recv() for remote in self.remotes]
        self.reset_infos = [info for r in results for info in r[1]]
        self._reset_seeds()
        self._reset_options()
        return np.concatenate([r[0] for r in results])

    def close(self) -> None:
        if self.closed:
            return
        for remote in self._pending:  # replies still owed by a step interrupted midway
            if remote.poll(10):
                remote.recv()
        for remote in self.remotes:
            try:
                remote.send(("close", None))
            except (BrokenPipeError, EOFError):
                pass
        for process in self.processes:
            process.join(timeout=10)
            if process.is_alive():
                process.terminate()
        self.closed = True

    # ------------------------------------------------------------------ attribute access
    def _by_worker(self, indices: VecEnvIndices) -> list[tuple[int, list[int]]]:
        """(worker, local indices) for the requested global indices, in order."""
        out = []
        for worker, part in enumerate(self._slices):
            local = [i - part.start for i in self._get_indices(indices) if part.start <= i < part.stop]
            if local:
                out.append((worker, local))
        return out

    def _ask(self, cmd: str, indices: VecEnvIndices, *payload: Any) -> list[Any]:
        plan = self._by_worker(indices)
        for worker, local in plan:
            self.remotes[worker].send((cmd, (local, *payload)))
        return [value for worker, _ in plan for value in self.remotes[worker].recv()]

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        return self._ask("get_attr", indices, attr_name)

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        self._ask("set_attr", indices, attr_name, value)

    def env_method(self, method_name: str, *method_args, indices: VecEnvIndices = None, **method_kwargs) -> list[Any]:
        return self._ask("env_method", indices, method_name, method_args, method_kwargs)

    def env_is_wrapped(self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None) -> list[bool]:
        return self._ask("is_wrapped", indices, wrapper_class)
