"""An evaluation's runs on Ray: on a cluster, or on a local Ray started for the command.

Only where the runs execute changes. The driver takes the pending runs from
``results.db`` (:func:`~rayreach.evaluate.runner.pending_jobs`) and stores each record as it
comes back (:func:`~rayreach.evaluate.runner.evaluate`), so the rows are the process
pool's and an interrupted evaluation resumes the same way. Each Ray actor holds one
:class:`~rayreach.evaluate.runner.Worker`, as each pool process does, so the PyBullet worlds
and the loaded policies are kept across runs instead of being built for every run.

Ray is optional (``pip install rayreach[ray]``); this module imports it only when called.
"""

from __future__ import annotations

import time
from collections import deque
from pathlib import Path
from typing import Any, Iterator

from rayreach.evaluate.executor import RunRecord
from rayreach.evaluate.runner import EvaluationConfig, Job, Worker, crash_record, evaluate, run_seed

INSTALL_HINT = "pip install rayreach[ray]"

STUCK_GRACE = 30.0
"""Seconds past ``run_timeout`` after which the driver stops an actor whose run never
returned (its alarm cannot interrupt a call stuck in C code) and stores the run as a crash."""

RETRIES = 1
"""Times a run whose actor died (a segfault, a lost node) is given to a fresh actor before
it is stored as a crash: a lost node is not the planner's fault, a run that kills its
process every time is."""

POLL = 1.0
"""Seconds between the driver's checks for overrun actors while it waits for results."""


class RayNotInstalled(ImportError, ValueError):
    """``--ray`` without Ray; a ValueError too, so the command prints it as a usage error."""


def import_ray() -> Any:
    """The ``ray`` module, or an error that says how to install it."""
    try:
        import ray
    except ImportError as exc:
        raise RayNotInstalled(f"Ray is not installed ({exc}); {INSTALL_HINT}") from exc
    return ray


class RunActor:
    """One Ray actor's :class:`Worker`; made remote by :class:`RayBackend`, so that this
    module imports without Ray."""

    def __init__(self, config: EvaluationConfig) -> None:
        self.worker = Worker(config)

    def ready(self) -> bool:
        return True

    def run(self, job: Job) -> tuple[Job, str, RunRecord]:
        robot, record = self.worker.run(*job)
        return job, robot, record


class RayBackend:
    """Runs jobs on ``actors`` Ray actors, one run in flight on each, yielding each record
    as it arrives (a :data:`~rayreach.evaluate.runner.Backend`)."""

    def __init__(self, ray: Any, actors: int) -> None:
        if actors < 1:
            raise ValueError(f"a Ray evaluation needs at least 1 actor, got {actors}")
        self.ray = ray
        self.actors = actors
        self.live: list[Any] = []

    def _start(self, remote: Any, config: EvaluationConfig, flight: dict[Any, tuple[Any, Job | None, float]]) -> None:
        """A new actor; its ``ready`` call goes in flight, and its first run is submitted once
        it answers, so that a run's clock starts when the actor is there to run it."""
        actor = remote.remote(config)
        self.live.append(actor)
        flight[actor.ready.remote()] = (actor, None, time.monotonic())

    def _stop(self, actor: Any) -> None:
        self.live.remove(actor)
        self.ray.kill(actor)

    def __call__(self, config: EvaluationConfig, jobs: list[Job]) -> Iterator[tuple[Job, str, RunRecord]]:
        if not jobs:
            return
        ray = self.ray
        remote = ray.remote(num_cpus=1, max_restarts=0)(RunActor)
        queue = deque(jobs)
        deaths: dict[Job, int] = {}
        robots: dict[str, str] = {}
        flight: dict[Any, tuple[Any, Job | None, float]] = {}
        """Ref: (actor, its job or None for its ``ready`` call, submit time)."""

        def submit(actor: Any) -> None:
            if queue:
                job = queue.popleft()
                flight[actor.run.remote(job)] = (actor, job, time.monotonic())
            else:  # nothing left for it: free its CPU for the others' retries
                self._stop(actor)

        def crash(job: Job, message: str) -> tuple[Job, str, RunRecord]:
            experiment, planner, run = job
            return job, robots.get(experiment, "?"), crash_record(planner, experiment, run_seed(experiment, run),
                                                                  message)

        for _ in range(min(self.actors, len(jobs))):
            self._start(remote, config, flight)
        while flight:
            ready, _ = ray.wait(list(flight), num_returns=1, timeout=POLL)
            for ref in ready:
                actor, job, _ = flight.pop(ref)
                try:
                    result = ray.get(ref)
                except ray.exceptions.RayActorError as exc:
                    if job is None:
                        raise RuntimeError(f"a Ray actor could not start ({exc}); is rayreach installed, in this "
                                           "version, on every node of the cluster?") from exc
                    self._stop(actor)
                    deaths[job] = deaths.get(job, 0) + 1
                    if deaths[job] <= RETRIES:
                        queue.appendleft(job)
                    else:
                        yield crash(job, f"ActorDied: the Ray actor died {deaths[job]} times on this run ({exc})")
                    if queue:
                        self._start(remote, config, flight)
                    continue
                if job is not None:
                    job, robot, record = result
                    robots[job[0]] = robot
                    yield job, robot, record
                submit(actor)
            now = time.monotonic()
            for ref, (actor, job, started) in list(flight.items()):
                if job is not None and now - started > config.run_timeout + STUCK_GRACE:
                    del flight[ref]
                    self._stop(actor)
                    yield crash(job, f"RunTimeout: run exceeded {config.run_timeout:g} s and did not stop; "
                                     "its Ray actor was killed")
                    if queue:
                        self._start(remote, config, flight)

    def close(self) -> None:
        for actor in list(self.live):
            self._stop(actor)


def evaluate_on_ray(config: EvaluationConfig, out: str | Path, address: str | None = None,
                    actors: int | None = None, progress: bool = True) -> Path:
    """:func:`~rayreach.evaluate.runner.evaluate` with the runs on Ray; returns the database path.

    ``address`` None: a local Ray of ``config.workers`` CPUs, started and shut down here;
    otherwise ``ray.init(address=...)`` (``auto``, ``ray://host:10001``). A Ray already
    initialised in this process is used as it is and left running. ``actors``: runs at once
    (default ``config.workers`` locally, the cluster's CPUs on a cluster)."""
    ray = import_ray()
    started = not ray.is_initialized()
    if started and address is None:
        ray.init(num_cpus=config.workers, include_dashboard=False, log_to_driver=False)
    elif started:
        ray.init(address=address)
    try:
        if actors is None:
            actors = config.workers if address is None else max(1, int(ray.cluster_resources().get("CPU", 1)))
        backend = RayBackend(ray, actors)
        try:
            return evaluate(config, out, progress=progress, backend=backend)
        finally:
            backend.close()
    finally:
        if started:
            ray.shutdown()
