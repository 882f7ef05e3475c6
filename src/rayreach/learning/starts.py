"""Several seeds started side by side; the one that learns best continues the run.

Whether PPO finds a way through a narrow opening depends on the seed: of four KR16 runs of
the default recipe, one never learned to enter the shelf, and its score alone on validation
worlds showed it by 5 M decisions (51 % against 89 to 92 %, docs/training.md). So a run with
``TrainConfig.starts`` > 1 first trains ``starts`` seeds (``seed``, ``seed + 1``, ...) for
``start_decisions`` decisions each, side by side in their own processes on
``workers // starts`` cores, in ``OUT/starts/seed-S``. Each judges its last checkpoint on the
selection worlds (``rayreach.learning.selection``); the best one's checkpoint, curves and
best.zip are copied to ``OUT`` with ``starts.json`` saying why, and the run goes on from
there as any resumed run. Two processes of one worker each stepped about 1.45 times the
decisions per second of one run with two (docs/performance.md), so the second start costs
about a third of its decisions in wall time.

An interrupted run resumes with ``--resume``: the starts go on from their checkpoints, and
once ``OUT`` holds a checkpoint the choice is made and the run resumes from it.
"""

from __future__ import annotations

import csv
import json
import multiprocessing as mp
import os
import shutil
import signal
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Callable, Sequence

from rayreach.learning import selection
from rayreach.learning.bundles import CheckpointError
from rayreach.learning.sweep import Trial, run_trial
from rayreach.learning.train import CHECKPOINT, CURVE, TrainConfig, train

STARTS_DIR = "starts"
STARTS_JSON = "starts.json"
CARRIED = (CURVE, selection.VALIDATION_CSV, selection.BEST)
"""Files of the chosen start that the run keeps (its checkpoint is copied last)."""
POLL_S = 5.0
"""Seconds between looks at the starts' progress."""
STOP_WAIT_S = 120.0
"""Seconds an interrupted run waits for its starts to write their checkpoints."""

HeatRunner = Callable[[Sequence[Trial], str], dict[str, str]]
"""Runs the starts' trials; returns the error of each trial that failed, by name."""


@dataclass(frozen=True)
class StartResult:
    """One start's verdict at its end: its last validation on the selection worlds."""

    seed: int
    score: float | None
    """Success less collisions alone (None: it failed, or never validated)."""
    row: dict[str, float] | None = None
    error: str | None = None


def plan_starts(config: TrainConfig, out: Path) -> list[Trial]:
    """One trial per start: its own seed, its share of the cores, ``start_decisions`` decisions
    and a validation at its end at least (the judge needs one)."""
    workers = max(1, config.workers // config.starts)
    every = min(config.validate_every or config.start_decisions, config.start_decisions)
    return [Trial(f"seed-{seed}", replace(config, seed=seed, workers=workers, timesteps=config.start_decisions,
                                          validate_every=every), out / STARTS_DIR / f"seed-{seed}")
            for seed in range(config.seed, config.seed + config.starts)]


def judge(trials: Sequence[Trial], errors: dict[str, str]) -> list[StartResult]:
    """Each start's last validation row (that of the checkpoint it ended on)."""
    results = []
    for trial in trials:
        rows = selection.read_validation(trial.out)
        error = errors.get(trial.name)
        if error is None and not rows:
            error = "no validation on record"
        row = rows[-1] if rows and error is None else None
        results.append(StartResult(trial.config.seed, row["score"] if row else None, row, error))
    return results


def choose(results: Sequence[StartResult]) -> StartResult:
    """The start with the best score; a tie goes to the lower seed."""
    judged = [r for r in results if r.score is not None]
    if not judged:
        raise RuntimeError("no start finished with a validation: "
                           + "; ".join(f"seed {r.seed}: {r.error}" for r in results))
    return max(judged, key=lambda r: (r.score, -r.seed))


def carry_over(trial: Trial, out: Path, report: dict[str, Any]) -> None:
    """Make ``out`` the chosen start's run: its files, ``starts.json``, then its checkpoint,
    whose arrival marks the choice as made."""
    for name in CARRIED:
        if (trial.out / name).exists():
            shutil.copyfile(trial.out / name, out / name)
    (out / STARTS_JSON).write_text(json.dumps(report, indent=2) + "\n")
    partial = out / (CHECKPOINT + ".part")
    shutil.copyfile(trial.out / CHECKPOINT, partial)
    os.replace(partial, out / CHECKPOINT)


def train_with_starts(config: TrainConfig, out: str | Path, resume: bool = False, command: str = "",
                      resume_overrides: dict[str, Any] | None = None, runner: HeatRunner | None = None,
                      **train_kwargs: Any) -> Path:
    """``train`` for a config with ``starts`` > 1 (with one, ``train`` itself); the same
    arguments, and the same model bundle at the end. ``runner`` runs the starts (default:
    side by side in processes)."""
    out = Path(out)
    if config.starts <= 1 or (resume and (out / CHECKPOINT).exists()):
        return train(config, out, resume=resume, command=command, resume_overrides=resume_overrides, **train_kwargs)
    if not resume and ((out / CHECKPOINT).exists() or (out / STARTS_DIR).exists()):
        raise CheckpointError(f"{out} holds a run already: pass --resume to continue it, or choose another --out")
    if resume and not (out / STARTS_DIR).exists():
        raise CheckpointError(f"--resume: no checkpoint at {out / CHECKPOINT} and no starts in {out / STARTS_DIR}")
    out.mkdir(parents=True, exist_ok=True)
    trials = plan_starts(config, out)
    started = time.time()
    errors = (runner or run_in_processes)(trials, command)
    results = judge(trials, errors)
    chosen = choose(results)
    report = {"chosen_seed": chosen.seed, "start_decisions": config.start_decisions,
              "wall_time_s": round(time.time() - started, 1),
              "starts": [{"seed": r.seed, "score": r.score, "validation": r.row, "error": r.error} for r in results]}
    carry_over(next(t for t in trials if t.config.seed == chosen.seed), out, report)
    print(f"starts: seed {chosen.seed} continues (" + ", ".join(
        f"seed {r.seed}: {'failed' if r.score is None else f'{r.score:.3f}'}" for r in results) + ")", flush=True)
    overrides = {"validate_every": config.validate_every, "checkpoint_every": config.checkpoint_every,
                 **(resume_overrides or {})}
    return train(config, out, resume=True, command=command, resume_overrides=overrides, **train_kwargs)


# ---------------------------------------------------------------------- processes
def _run_start(trial: Trial, command: str, log: str) -> None:
    """A start in its own process, all its output in its log (PyBullet's and a traceback's too)."""
    fd = os.open(log, os.O_WRONLY | os.O_CREAT | os.O_APPEND)
    os.dup2(fd, sys.stdout.fileno())
    os.dup2(fd, sys.stderr.fileno())
    os.close(fd)
    run_trial(trial, command=command)


def _decisions_done(trial: Trial) -> int:
    """Decisions a start has made so far, by its learning curve's last row."""
    path = trial.out / CURVE
    if not path.exists():
        return 0
    with path.open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    return int(float(rows[-1]["timesteps"])) if rows else 0


def run_in_processes(trials: Sequence[Trial], command: str) -> dict[str, str]:
    """Each start in a process of its own (spawned: torch and PyBullet do not survive a
    fork), with one progress bar for all. Ctrl-C reaches the starts too; a SIGTERM is passed
    on. Either way each writes its checkpoint, and the run stops with ``KeyboardInterrupt``."""
    from tqdm import tqdm

    context = mp.get_context("spawn")
    procs = []
    for trial in trials:
        trial.out.mkdir(parents=True, exist_ok=True)
        proc = context.Process(target=_run_start, args=(trial, command, str(trial.out / "train.log")),
                               name=trial.name)
        proc.start()
        procs.append(proc)

    def pass_on(signum, frame):
        for proc in procs:
            if proc.is_alive():
                os.kill(proc.pid, signal.SIGTERM)
        raise KeyboardInterrupt

    previous = signal.signal(signal.SIGTERM, pass_on)
    total = sum(t.config.timesteps for t in trials)
    bar = tqdm(total=total, unit="step", dynamic_ncols=True, desc=f"{len(trials)} starts", smoothing=0.05)
    try:
        while any(proc.is_alive() for proc in procs):
            for proc in procs:
                proc.join(POLL_S / len(procs))
            bar.n = min(total, sum(_decisions_done(t) for t in trials))
            bar.refresh()
    except KeyboardInterrupt:
        for proc in procs:
            proc.join(STOP_WAIT_S)
        raise KeyboardInterrupt("interrupted while the starts trained; resume with --resume") from None
    finally:
        signal.signal(signal.SIGTERM, previous)
        bar.close()
    return {t.name: f"exit code {p.exitcode}, see {t.out / 'train.log'}"
            for t, p in zip(trials, procs) if p.exitcode != 0}

