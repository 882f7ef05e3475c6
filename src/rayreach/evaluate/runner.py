"""Run every (experiment, planner, run) through the executor, in worker processes, storing
each finished run at once so an interrupted evaluation resumes where it stopped."""

from __future__ import annotations

import multiprocessing as mp
import os
import signal
from collections import OrderedDict
from dataclasses import dataclass, field
from importlib import metadata
from pathlib import Path
from typing import Any, Callable, Iterator

from tqdm import tqdm

from rayreach.evaluate.store import ResultsStore
from rayreach.evaluate.executor import ExecutionConfig, Executor, RunRecord
from rayreach.planners import PLANNER_NAMES, GlobalPlanner, ReactivePlanner, make_planner
from rayreach.robots import get_robot
from rayreach.scenarios import EXPERIMENTS, RANDOM, WORLD_SUITES, check_suite
from rayreach.scenarios.splits import EVALUATION_SPLITS, get_split

SUITE_PREFIXES = tuple(f"{suite}-" for suite in WORLD_SUITES)
"""Experiment names ``random-ur5@test`` / ``random-kr16@validation``: random worlds of that
robot from that seed split (``rayreach.scenarios.splits``), with ``EvaluationConfig.obstacles``
each; ``random-ur5:2@test``: with 2 obstacles each. ``broad-ur5@test``: the same of the broad
suite (``rayreach.scenarios.suites``)."""


def is_drawn(experiment: str) -> bool:
    """Whether ``experiment`` names worlds drawn from a suite (``random-...``, ``broad-...``)."""
    return experiment.startswith(SUITE_PREFIXES)

UNSPLIT = "validation"
"""The split of a random experiment named without one (``random-ur5``, ``random-ur5:2``):
databases from before names carried the split drew from seed 1,000,000 on, the validation range."""

EXECUTORS_KEPT = 4
"""Executors (one PyBullet world each, about 56 MB) a worker keeps; the least recently used
is closed for a new scene, so a worker's memory stays flat however many scenes it runs."""


@dataclass(frozen=True)
class RandomExperiment:
    """What a ``SUITE-ROBOT[:N][@SPLIT]`` experiment name says."""

    robot: str
    obstacles: int
    split: str
    suite: str = RANDOM


def random_experiment(robot: str, obstacles: int | None = None, split: str = "test", suite: str = RANDOM) -> str:
    """The experiment name of ``robot``'s worlds of ``suite`` from ``split`` (``obstacles``
    None: the config's count); the split is part of the name so its results never mix with
    another's."""
    if split not in EVALUATION_SPLITS:
        raise ValueError(f"unknown evaluation split '{split}'; valid: {', '.join(EVALUATION_SPLITS)}")
    check_suite(suite)
    return f"{suite}-{robot}" + ("" if obstacles is None else f":{obstacles}") + f"@{split}"


def parse_random(experiment: str, default_obstacles: int) -> RandomExperiment:
    """Robot, obstacles per world, seed split and suite of a ``SUITE-ROBOT[:N][@SPLIT]`` name."""
    suite, _, rest = experiment.partition("-")
    body, at, split = rest.partition("@")
    if not at:
        split = UNSPLIT
    elif split not in EVALUATION_SPLITS:
        raise ValueError(f"'{experiment}': unknown split '{split}' after '@'; "
                         f"valid: {', '.join(EVALUATION_SPLITS)}")
    robot, _, count = body.partition(":")
    if not count:
        return RandomExperiment(robot, default_obstacles, split, suite)
    if not count.isdigit():
        raise ValueError(f"'{experiment}': the obstacle count after ':' must be a whole number, "
                         "e.g. random-ur5:2@test")
    return RandomExperiment(robot, int(count), split, suite)


@dataclass(frozen=True)
class EvaluationConfig:
    experiments: tuple[str, ...]
    """``exp1``..``exp7``, ``random-ur5@test``, ``random-kr16@validation`` (``random-ur5:2@test``:
    2 obstacles per world) or scene files."""
    planners: tuple[str, ...]
    runs: int = 30
    workers: int = field(default_factory=lambda: os.cpu_count() or 1)
    time_limit: float = 30.0
    """Planning time limit of the sampling planners per query, s."""
    run_timeout: float = 180.0
    """A run still going after this many seconds is stopped and stored as a crash."""
    smooth: bool = False
    replan: bool = False
    obstacles: int = 3
    """Obstacles per random world (the training curriculum's maximum)."""
    models: tuple[tuple[str, str], ...] = ()
    """(robot, model path) overriding the shipped DRL policies."""

    def __post_init__(self) -> None:
        unknown = [p for p in self.planners if p not in PLANNER_NAMES]
        if unknown:
            raise ValueError(f"unknown planner(s) {unknown}; valid: {', '.join(PLANNER_NAMES)}")
        if self.runs < 1 or self.workers < 1:
            raise ValueError(f"runs and workers must be >= 1, got {self.runs} and {self.workers}")
        for experiment in self.experiments:  # here, not as 500 crash records from the workers
            if is_drawn(experiment):
                get_robot(parse_random(experiment, self.obstacles).robot)


def parse_experiments(text: str) -> tuple[str, ...]:
    """``1-7``, ``1,3``, ``exp4`` or ``random-ur5@test`` (mixed, comma-separated) to experiment names."""
    names: list[str] = []
    for part in (p.strip() for p in text.split(",") if p.strip()):
        if is_drawn(part) or part.endswith(".json"):
            names.append(part)
            continue
        bare = part.replace("exp", "")
        try:
            low, _, high = bare.partition("-")
            numbers = range(int(low), int(high or low) + 1)
        except ValueError:
            raise ValueError(f"cannot read experiment '{part}'; use e.g. 1-7, 1,3, exp4 or random-ur5@test") from None
        for n in numbers:
            if f"exp{n}" not in EXPERIMENTS:
                raise ValueError(f"no experiment {n}; known: {', '.join(EXPERIMENTS)}")
            names.append(f"exp{n}")
    return tuple(dict.fromkeys(names))


def run_seed(experiment: str, run: int) -> int:
    """The seed of run ``run``, the same for every planner; a random experiment's run ``run``
    plays world ``run`` of its split."""
    if not is_drawn(experiment):
        return run
    return get_split(parse_random(experiment, EvaluationConfig.obstacles).split).seed(run)


def versions() -> dict[str, str]:
    out = {}
    for package in ("rayreach", "pybullet", "numpy", "torch", "stable-baselines3", "gymnasium", "ompl"):
        try:
            out[package] = metadata.version(package)
        except metadata.PackageNotFoundError:
            continue
    return out


class RunTimeout(Exception):
    pass


class Worker:
    """Keeps the executors of the last :data:`EXECUTORS_KEPT` experiments and one planner per
    (name, robot) across runs."""

    def __init__(self, config: EvaluationConfig, keep: int = EXECUTORS_KEPT) -> None:
        if keep < 1:
            raise ValueError(f"a worker keeps at least 1 executor, got {keep}")
        self.config = config
        self.keep = keep
        self.executors: OrderedDict[str, Executor] = OrderedDict()
        """Least recently used first."""
        self.planners: dict[tuple[str, str], GlobalPlanner | ReactivePlanner] = {}

    def executor(self, experiment: str) -> Executor:
        if experiment in self.executors:
            self.executors.move_to_end(experiment)
            return self.executors[experiment]
        while len(self.executors) >= self.keep:  # before building: one world fewer at the peak
            self.executors.popitem(last=False)[1].close()
        exec_config = ExecutionConfig(replan=self.config.replan)
        if is_drawn(experiment):
            suite = parse_random(experiment, self.config.obstacles)
            ex = Executor(suite.suite, robot=suite.robot, config=exec_config)
            ex.env.set_n_obstacles(suite.obstacles)
        else:
            ex = Executor(experiment, config=exec_config)
        self.executors[experiment] = ex
        return ex

    def planner(self, name: str, robot: str) -> GlobalPlanner | ReactivePlanner:
        if (name, robot) not in self.planners:
            models = dict(self.config.models)
            self.planners[(name, robot)] = make_planner(name, robot, model=models.get(robot),
                                                        time_limit=self.config.time_limit, smooth=self.config.smooth)
        return self.planners[(name, robot)]

    def run(self, experiment: str, planner: str, run: int) -> tuple[str, RunRecord]:
        """(robot, record); a planner that raises or overruns ``run_timeout`` gives a crash record."""
        seed = run_seed(experiment, run)
        robot = "?"

        def overrun(signum: int, frame: Any) -> None:
            raise RunTimeout(f"run exceeded {self.config.run_timeout:g} s")

        previous = signal.signal(signal.SIGALRM, overrun)
        signal.setitimer(signal.ITIMER_REAL, self.config.run_timeout)
        try:
            ex = self.executor(experiment)
            robot = ex.robot
            return robot, ex.run(self.planner(planner, robot), seed)
        except Exception as exc:  # recorded, and the evaluation goes on
            return robot, crash_record(planner, experiment, seed, f"{type(exc).__name__}: {exc}")
        finally:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, previous)

    def close(self) -> None:
        for ex in self.executors.values():
            ex.close()
        self.executors.clear()


def crash_record(planner: str, experiment: str, seed: int, message: str) -> RunRecord:
    nan = float("nan")
    return RunRecord(planner=planner, scenario=experiment, seed=seed, outcome="crash", plan_status="crash",
                     success=False, collision=False, path_length=nan, path_length_unsmoothed=nan,
                     joint_path_length=nan, planning_time=0.0, motion_time=0.0, execution_time=0.0, steps=0,
                     message=message)


_worker: Worker | None = None


def _init_worker(config: EvaluationConfig) -> None:
    global _worker
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent handles Ctrl-C
    _worker = Worker(config)


def _run_job(job: tuple[str, str, int]) -> tuple[tuple[str, str, int], str, RunRecord]:
    assert _worker is not None
    robot, record = _worker.run(*job)
    return job, robot, record


def pending_jobs(config: EvaluationConfig, done: set[tuple[str, str, int]]) -> list[tuple[str, str, int]]:
    """Unfinished (experiment, planner, run), run-major so a partial evaluation covers every
    planner alike."""
    return [(e, p, r) for e in config.experiments for r in range(config.runs) for p in config.planners
            if (e, p, r) not in done]


Job = tuple[str, str, int]
"""(experiment, planner, run)."""
Backend = Callable[[EvaluationConfig, list[Job]], Iterator[tuple[Job, str, RunRecord]]]
"""What runs the pending jobs: yields (job, robot, record) as each finishes, in any order."""


def evaluate(config: EvaluationConfig, out: str | Path, progress: bool = True,
             backend: Backend | None = None) -> Path:
    """Run what ``out/results.db`` does not hold yet; returns the database path.

    ``backend``: what runs the jobs (default: the process pool; ``ray_runner`` passes Ray's),
    so every backend stores the same rows and resumes from the same store."""
    from rayreach.learning.train import git_commit

    out = Path(out)
    store = ResultsStore(out / "results.db")
    jobs = pending_jobs(config, store.done())
    meta = versions(), git_commit()
    bar = tqdm(total=len(jobs), desc="evaluate", unit="run", disable=not progress)
    try:
        for (experiment, planner, run), robot, record in (backend or _results)(config, jobs):
            store.add(experiment, robot, ExecutionConfig().goal_tolerance, run, record, *meta)
            bar.set_postfix_str(f"{experiment} {planner} #{run}: {record.outcome}")
            bar.update()
    finally:
        bar.close()
        store.close()
    return out / "results.db"


def _results(config: EvaluationConfig, jobs: list[tuple[str, str, int]]
             ) -> Iterator[tuple[tuple[str, str, int], str, RunRecord]]:
    if not jobs:
        return
    if config.workers == 1:
        worker = Worker(config)
        try:
            for job in jobs:
                robot, record = worker.run(*job)
                yield job, robot, record
        finally:
            worker.close()
        return
    context = mp.get_context("spawn")
    with context.Pool(min(config.workers, len(jobs)), initializer=_init_worker, initargs=(config,)) as pool:
        yield from pool.imap_unordered(_run_job, jobs)
