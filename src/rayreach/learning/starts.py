"""Several seeds started side by side; the one that learns best continues the run.

Whether PPO finds a way through a narrow opening depends on the seed: of four KR16 runs of
the default recipe, one never learned to enter the shelf, and its score alone on validation
worlds showed it by 5 M decisions (51 % against 89 to 92 %, docs/training.md). So a run with
``TrainConfig.starts`` > 1 first trains ``starts`` seeds (``seed``, ``seed + 1``, ...) for
``start_decisions`` decisions each, side by side in their own processes on
``workers // starts`` cores, in ``OUT/starts/seed-S``. Each is judged on the checkpoint it
ended on, on the selection worlds (``rayreach.learning.selection``); the best one's
checkpoint, curves and best.zip are copied to ``OUT`` with ``starts.json`` saying why, and
the run goes on from there as any resumed run. Two KR16 runs of one worker each stepped
1.36 times the decisions per second of one run with two, so a second start of 5 M
decisions adds about 5 minutes on two cores (docs/training.md, "Several starts").

An interrupted run resumes with ``--resume``: the starts go on from their checkpoints, and
once ``OUT`` holds a checkpoint the choice is made and the run resumes from it. A start that
stops before its end (killed, out of memory) holds the choice back until it is resumed.
"""

from __future__ import annotations

import csv
import json
import multiprocessing as mp
import os
import shutil
import signal
import sys
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Callable, Sequence

from rayreach.learning import selection
from rayreach.learning.bundles import CheckpointError, copy_bundle, read_bundle_meta
from rayreach.learning.run_lock import held
from rayreach.learning.sweep import Trial, run_trial
from rayreach.learning.train import CHECKPOINT, CURVE, TrainConfig, append_curve, train

STARTS_DIR = "starts"
STARTS_JSON = "starts.json"
CARRIED = (CURVE, selection.VALIDATION_CSV, selection.BEST)
"""Files of the chosen start that the run keeps (its checkpoint is copied last)."""
POLL_S = 5.0
"""Seconds between looks at the starts' progress."""

StartsRunner = Callable[[Sequence[Trial], str], dict[str, str]]
"""Runs the starts' trials; returns the error of each trial that stopped early, by name."""


@dataclass(frozen=True)
class StartResult:
    """One start's verdict on the checkpoint it ended on."""

    seed: int
    row: dict[str, float]
    """Its validation row (``selection.validate`` with the step count and wall time)."""
    wall_time: float
    """Seconds its training took."""

    @property
    def score(self) -> float:
        return self.row["score"]


def plan_starts(config: TrainConfig, out: Path) -> list[Trial]:
    """One trial per start: the run's config with its own seed, its share of the cores and
    ``start_decisions`` decisions."""
    workers = max(1, config.workers // config.starts)
    return [Trial(f"seed-{seed}", replace(config, seed=seed, workers=workers, timesteps=config.start_decisions),
                  out / STARTS_DIR / f"seed-{seed}")
            for seed in range(config.seed, config.seed + config.starts)]


def judge(trial: Trial) -> StartResult:
    """A start's verdict on its last checkpoint: the start's own validation of it where it
    made one, else one made now (a start that validates less often than it runs, or whose
    last validation failed)."""
    meta, _ = read_bundle_meta(trial.out / CHECKPOINT)
    steps = int(meta["timesteps"])
    rows = [r for r in selection.read_validation(trial.out) if int(r["timesteps"]) == steps]
    if rows:
        row = rows[-1]
    else:
        config = trial.config
        verdict = selection.validate(trial.out / CHECKPOINT, config.robot, config.suite, config.validate_worlds)
        row = {"timesteps": steps, "wall_time": meta["wall_time_s"], **verdict}
        append_curve(trial.out / selection.VALIDATION_CSV, row)
    return StartResult(trial.config.seed, row, float(meta["state"]["wall_time"]))


def choose(results: Sequence[StartResult]) -> StartResult:
    """The start with the best score; a tie goes to the lower seed."""
    return max(results, key=lambda r: (r.score, -r.seed))


def carry_over(trial: Trial, out: Path, report: dict[str, Any], wall_time: float) -> None:
    """Make ``out`` the chosen start's run: its files, ``starts.json``, then its checkpoint
    with the starts' wall time (they ran side by side: the longest), whose arrival marks the
    choice as made."""
    for name in CARRIED:
        if (trial.out / name).exists():
            shutil.copyfile(trial.out / name, out / name)
    (out / STARTS_JSON).write_text(json.dumps(report, indent=2) + "\n")
    meta, _ = read_bundle_meta(trial.out / CHECKPOINT)
    meta["state"]["wall_time"] = wall_time
    meta["wall_time_s"] = round(wall_time, 1)
    copy_bundle(trial.out / CHECKPOINT, out / CHECKPOINT, meta)


def train_with_starts(config: TrainConfig, out: str | Path, resume: bool = False, command: str = "",
                      resume_overrides: dict[str, Any] | None = None, runner: StartsRunner | None = None,
                      **train_kwargs: Any) -> Path:
    """``train`` for a config with ``starts`` > 1 (with one, or with no more decisions than
    a start's, ``train`` itself); the same arguments, and the same model bundle at the end.
    ``runner`` runs the starts (default: side by side in processes)."""
    out = Path(out)
    if config.starts <= 1 or config.start_decisions >= config.timesteps or (resume and (out / CHECKPOINT).exists()):
        return train(config, out, resume=resume, command=command, resume_overrides=resume_overrides, **train_kwargs)
    if any(train_kwargs.values()):
        raise ValueError(f"{', '.join(k for k, v in train_kwargs.items() if v)} apply to one part of a run: give "
                         "them to a --resume after its starts have chosen")
    if resume and not (out / STARTS_DIR).exists():
        raise CheckpointError(f"--resume: no checkpoint at {out / CHECKPOINT} and no starts in {out / STARTS_DIR}")
    with held(out):  # from the check to the chosen run's end, which takes it again within this process
        if not resume:
            for name in (CHECKPOINT, STARTS_DIR, selection.BEST):
                if (out / name).exists():
                    raise CheckpointError(f"{out / name} is left from an earlier run: pass --resume to continue it, "
                                          "or choose another --out")
        trials = plan_starts(config, out)
        errors = (runner or run_in_processes)(trials, command)
        if errors:
            raise RuntimeError("the choice waits for every start; " + "; ".join(f"{k}: {v}" for k, v in errors.items())
                               + "; resume with --resume")
        results = [judge(trial) for trial in trials]
        chosen = choose(results)
        wall_time = max(r.wall_time for r in results)
        report = {"chosen_seed": chosen.seed, "start_decisions": config.start_decisions,
                  "wall_time_s": round(wall_time, 1),
                  "starts": [{"seed": r.seed, "score": r.score, "wall_time_s": round(r.wall_time, 1),
                              "validation": r.row} for r in results]}
        carry_over(next(t for t in trials if t.config.seed == chosen.seed), out, report, wall_time)
        print(f"starts: seed {chosen.seed} continues ("
              + ", ".join(f"seed {r.seed}: {r.score:.3f}" for r in results) + ")", flush=True)
        return train(config, out, resume=True, command=command,
                     resume_overrides=resume_overrides if resume else None, **train_kwargs)


# ---------------------------------------------------------------------- processes
def _run_start(trial: Trial, command: str, log: str) -> None:
    """A start in its own process and process group (a terminal's Ctrl-C goes to the parent,
    which passes one SIGTERM on), all its output in its log (PyBullet's and a traceback's too)."""
    os.setpgrp()
    fd = os.open(log, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
    os.dup2(fd, sys.stdout.fileno())
    os.dup2(fd, sys.stderr.fileno())
    os.close(fd)
    run_trial(trial, command=command)


def _decisions_done(trial: Trial) -> int:
    """Decisions a start has made so far, by its learning curve's last row (0 while unread)."""
    try:
        with (trial.out / CURVE).open(newline="") as handle:
            rows = list(csv.DictReader(handle))
        return int(float(rows[-1]["timesteps"]))
    except (OSError, csv.Error, ValueError, KeyError, IndexError):
        return 0


def run_in_processes(trials: Sequence[Trial], command: str) -> dict[str, str]:
    """Each start in a process of its own (spawned: torch and PyBullet do not survive a
    fork), with one progress bar for all. Ctrl-C or SIGTERM sends each start one SIGTERM, on
    which it writes its checkpoint; once all have stopped, ``KeyboardInterrupt``."""
    from tqdm import tqdm

    context = mp.get_context("spawn")
    procs = []
    for trial in trials:
        trial.out.mkdir(parents=True, exist_ok=True)
        proc = context.Process(target=_run_start, args=(trial, command, str(trial.out / "train.log")),
                               name=trial.name)
        proc.start()
        procs.append(proc)
    stopping: list[int] = []

    def stop(signum, frame):
        if not stopping:
            stopping.append(signum)
            for proc in procs:
                if proc.is_alive():
                    os.kill(proc.pid, signal.SIGTERM)

    previous = {sig: signal.signal(sig, stop) for sig in (signal.SIGINT, signal.SIGTERM)}
    total = sum(t.config.timesteps for t in trials)
    done = {t.name: 0 for t in trials}
    bar = tqdm(total=total, unit="step", dynamic_ncols=True, desc=f"{len(trials)} starts", smoothing=0.05)
    try:
        while any(proc.is_alive() for proc in procs):
            for proc in procs:
                proc.join(POLL_S / len(procs))
            done.update({t.name: max(done[t.name], _decisions_done(t)) for t in trials})
            bar.n = min(total, sum(done.values()))
            bar.refresh()
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        bar.close()
    if stopping:
        raise KeyboardInterrupt("interrupted while the starts trained; resume with --resume")
    return {t.name: f"exit code {p.exitcode}, see {t.out / 'train.log'}"
            for t, p in zip(trials, procs) if p.exitcode != 0}
