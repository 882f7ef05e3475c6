"""Several training runs at once: one trial per seed, or per value of one setting, each in its
own run directory, resumable, as plain Ray tasks or one after another.

``rayreach sweep --robot ur5 --seeds 0,1,2 [--set FIELD=V1,V2] --out runs/sweep [--ray [ADDRESS]]``
drives :func:`sweep`. Trial ``seed-S`` (``FIELD-VALUE-seed-S`` with ``--set``) trains into
``OUT/NAME`` with :func:`~rayreach.learning.train.train`. Whether a trial starts, resumes
or is done is decided when it runs, from what its directory holds, so a sweep that was
stopped (or a Ray task retried on another node) goes on from each trial's last checkpoint.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any, Callable, Sequence

from rayreach.learning.bundles import CheckpointError, read_bundle_meta
from rayreach.learning.train import CHECKPOINT, MODEL, TrainConfig, train, with_envs

TRIAL_CPUS = 2
"""CPUs a trial asks Ray for (and the ``workers`` its run then uses): a run's update uses
its cores well up to about two (docs/performance.md)."""

FIXED = ("seed", "robot", "recipe")
"""Fields ``--set`` may not sweep: seeds have ``--seeds``, a robot or recipe its own sweep."""

CANCEL_WAIT = 120.0
"""Seconds an interrupted Ray sweep waits for its trials to write their checkpoints."""

TrainFn = Callable[..., Path]


@dataclass(frozen=True)
class Trial:
    name: str
    """Its directory's name under the sweep's ``out``."""
    config: TrainConfig
    out: Path


def parse_seeds(text: str) -> tuple[int, ...]:
    """``0,1,2`` or ``0-4`` (mixed) to seeds."""
    seeds: list[int] = []
    for part in (p.strip() for p in text.split(",") if p.strip()):
        low, _, high = part.partition("-")
        try:
            seeds.extend(range(int(low), int(high or low) + 1))
        except ValueError:
            raise ValueError(f"cannot read seed '{part}'; use e.g. 0,1,2 or 0-4") from None
    if not seeds:
        raise ValueError("--seeds names no seed; use e.g. 0,1,2")
    return tuple(dict.fromkeys(seeds))


def _value(name: str, default: Any, text: str) -> Any:
    """``text`` as a value of the field whose default is ``default``."""
    annotation = str(next(f.type for f in fields(TrainConfig) if f.name == name))
    if text.lower() == "none" and "None" in annotation:
        return None
    kind = type(default) if default is not None else float
    if kind is bool:
        if text.lower() not in ("true", "false", "1", "0"):
            raise ValueError(f"--set {name}: '{text}' is not true or false")
        return text.lower() in ("true", "1")
    if kind in (int, float, str):
        try:
            return kind(text)
        except ValueError:
            raise ValueError(f"--set {name}: '{text}' is not a {kind.__name__}") from None
    raise ValueError(f"--set {name}: a {kind.__name__} field cannot be swept from the command line; "
                     "sweep a number, a flag or a name")


def parse_setting(text: str, base: TrainConfig) -> tuple[str, tuple[Any, ...]]:
    """``FIELD=V1,V2`` to the TrainConfig field and its values, typed as the field is."""
    name, eq, values = text.partition("=")
    name = name.strip()
    names = [f.name for f in fields(TrainConfig)]
    if not eq or not values.strip():
        raise ValueError(f"--set takes FIELD=V1,V2 (e.g. learning_rate=3e-4,1e-3), got '{text}'")
    if name not in names:
        raise ValueError(f"--set: TrainConfig has no field '{name}'; fields: {', '.join(names)}")
    if name in FIXED:
        raise ValueError(f"--set cannot sweep '{name}'" + ("; use --seeds" if name == "seed" else ""))
    parsed = tuple(_value(name, getattr(base, name), v.strip()) for v in values.split(",") if v.strip())
    return name, tuple(dict.fromkeys(parsed))


def _with(config: TrainConfig, name: str, value: Any) -> TrainConfig:
    return with_envs(config, value) if name == "envs" else replace(config, **{name: value})


def plan_trials(base: TrainConfig, out: str | Path, seeds: Sequence[int] = (0,),
                setting: tuple[str, Sequence[Any]] | None = None) -> list[Trial]:
    """One trial per seed, or per (value, seed) of ``setting`` (field, values); names are
    fixed by the arguments alone, so rerunning the same sweep finds the same directories."""
    out = Path(out)
    trials = []
    for value in (setting[1] if setting else (None,)):
        for seed in seeds:
            config = replace(base, seed=seed, starts=1)  # a sweep is its own set of seeds
            name = f"seed-{seed}"
            if setting:
                config = _with(config, setting[0], value)
                name = f"{setting[0]}-{value}-{name}"
            trials.append(Trial(name, config, out / name))
    if len({t.name for t in trials}) < len(trials):
        raise ValueError("two trials of this sweep would share a directory; give each value once")
    return trials


def trial_state(trial: Trial) -> str:
    """``done`` (its model has the steps asked for), ``resume`` (a checkpoint to go on from)
    or ``new``."""
    model = trial.out / MODEL
    if model.exists():
        try:
            meta, _ = read_bundle_meta(model)
        except CheckpointError:
            meta = {}
        if int(meta.get("timesteps", -1)) >= trial.config.timesteps:
            return "done"
    return "resume" if (trial.out / CHECKPOINT).exists() else "new"


def run_trial(trial: Trial, train_fn: TrainFn = train, command: str = "") -> Path:
    """Train, resume or skip ``trial`` by what its directory holds; its model's path."""
    state = trial_state(trial)
    if state == "done":
        return trial.out / MODEL
    return train_fn(trial.config, trial.out, resume=state == "resume", command=command)


@dataclass
class TrialResult:
    trial: Trial
    state: str
    """What the trial's directory held when the sweep started (``trial_state``)."""
    model: Path | None = None
    error: str | None = None
    seconds: float = 0.0


def _timed(trial: Trial, train_fn: TrainFn, command: str) -> tuple[Path, float]:
    start = time.monotonic()
    return run_trial(trial, train_fn, command), time.monotonic() - start


def sweep(trials: Sequence[Trial], ray_address: str | None = None, use_ray: bool = False,
          cpus: int = TRIAL_CPUS, train_fn: TrainFn = train, command: str = "",
          report: Callable[[TrialResult], None] | None = None) -> list[TrialResult]:
    """Run ``trials``; one that fails is reported and the others go on.

    Without ``use_ray`` they run here, one after another. With it each is a Ray task of
    ``cpus`` CPUs and ``workers=cpus`` (``ray_address`` None or ``local``: a local Ray of
    this machine's CPUs, shut down at the end; a Ray already initialised is used as it is).
    On a cluster ``out`` must be a directory every node sees. ``report`` is called as each
    trial ends."""
    results = {t.name: TrialResult(t, trial_state(t)) for t in trials}
    report = report or (lambda result: None)
    if not use_ray:
        for trial in trials:
            result = results[trial.name]
            try:
                result.model, result.seconds = _timed(trial, train_fn, command)
            except (ValueError, RuntimeError, OSError) as exc:
                result.error = f"{type(exc).__name__}: {exc}"
            report(result)
        return list(results.values())

    from rayreach.evaluate.ray_runner import import_ray

    ray = import_ray()
    started = not ray.is_initialized()
    if started:
        if ray_address in (None, "local"):
            ray.init(include_dashboard=False, log_to_driver=False)
        else:
            ray.init(address=ray_address)
    try:
        task = ray.remote(num_cpus=cpus)(_timed)
        refs = {task.remote(replace(t, config=replace(t.config, workers=cpus)), train_fn, command): t.name
                for t in trials}
        pending = list(refs)
        try:
            while pending:
                done, pending = ray.wait(pending, num_returns=1)
                result = results[refs[done[0]]]
                try:
                    result.model, result.seconds = ray.get(done[0])
                except ray.exceptions.RayError as exc:
                    cause = getattr(exc, "cause", None) or exc  # a task's own exception, not Ray's wrapper
                    result.error = f"{type(cause).__name__}: {cause}"
                report(result)
        except KeyboardInterrupt:
            for ref in pending:  # a KeyboardInterrupt in the trial: train() checkpoints, then stops
                ray.cancel(ref)
            ray.wait(pending, num_returns=len(pending), timeout=CANCEL_WAIT)
            raise
    finally:
        if started:
            ray.shutdown()
    return list(results.values())
