"""Evaluation and sweeps on Ray: a local Ray stores the process pool's rows and resumes the
same way, stuck and dying runs become crash records, the sweep's trials and their resume,
and the install hint where Ray is missing. One local Ray serves the whole module."""

from __future__ import annotations

import json
import math
import os
import shutil
import sqlite3
import subprocess
import sys
import time
import zipfile
from dataclasses import replace
from pathlib import Path

import pytest

ray = pytest.importorskip("ray")

from rayreach.evaluate import EvaluationConfig, evaluate  # noqa: E402
from rayreach.evaluate import ray_runner, runner  # noqa: E402
from rayreach.evaluate.ray_runner import RayBackend, RunActor, evaluate_on_ray  # noqa: E402
from rayreach.evaluate.store import ResultsStore  # noqa: E402
from rayreach.learning import sweep as sweeps  # noqa: E402
from rayreach.learning.bundles import FORMAT, META_ENTRY  # noqa: E402
from rayreach.learning.train import TrainConfig, with_envs  # noqa: E402
from rayreach.planners.base import GlobalPlanner  # noqa: E402

CONFIG = EvaluationConfig(("exp1",), ("ompl-rrtconnect", "drl-alone"), runs=2, workers=2)
"""RRTConnect: milliseconds a query, so no run nears the time limit however loaded the machine (RRT on
exp1 seed 0 plans for 10 s or more and may be cut)."""
QUICK = replace(CONFIG, planners=("ompl-rrtconnect",), runs=3)
"""For the resume tests: no policy to load in each new actor."""


@pytest.fixture(scope="module")
def local_ray():
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])  # the stand-ins below, in Ray's workers
    yield ray
    ray.cloudpickle.unregister_pickle_by_value(sys.modules[__name__])
    ray.shutdown()


def _rows(path: Path) -> list[dict]:
    store = ResultsStore(path)
    try:
        return store.rows()
    finally:
        store.close()


def _same_rows(got: list[dict], want: list[dict]) -> None:
    keys = ("planner", "experiment", "run", "seed", "status", "solved")
    assert [tuple(r[k] for k in keys) for r in got] == [tuple(r[k] for k in keys) for r in want]
    for a, b in zip(got, want):
        if b["solution_length"] is None:
            assert a["solution_length"] is None
        else:
            assert math.isclose(a["solution_length"], b["solution_length"], rel_tol=0, abs_tol=1e-9)


@pytest.fixture(scope="module")
def pool_rows(tmp_path_factory):
    out = tmp_path_factory.mktemp("pool")
    evaluate(CONFIG, out, progress=False)
    rows = _rows(out / "results.db")
    assert len(rows) == 4 and {r["planner"] for r in rows} == {"ompl-rrtconnect", "drl-alone"}
    return out, rows


def test_a_local_ray_evaluation_stores_the_pools_rows(local_ray, pool_rows, tmp_path):
    evaluate_on_ray(CONFIG, tmp_path, progress=False)
    rows = _rows(tmp_path / "results.db")
    _same_rows(rows, pool_rows[1])
    assert any(r["status"] == "success" for r in rows)  # not four matching crashes
    assert ray.is_initialized()  # a Ray it did not start is left running


def test_an_interrupted_ray_evaluation_resumes_without_repeating_stored_runs(local_ray, pool_rows, tmp_path,
                                                                            monkeypatch):
    add = ResultsStore.add
    stored = []

    def add_then_stop(self, *args):
        add(self, *args)
        stored.append(args)
        raise KeyboardInterrupt

    monkeypatch.setattr(ResultsStore, "add", add_then_stop)
    with pytest.raises(KeyboardInterrupt):
        evaluate_on_ray(QUICK, tmp_path, progress=False)
    monkeypatch.setattr(ResultsStore, "add", add)
    deadline = time.monotonic() + 30
    while ray.available_resources().get("CPU", 0) < 2 and time.monotonic() < deadline:
        time.sleep(0.2)
    assert ray.available_resources().get("CPU", 0) == 2  # the interrupted evaluation's actors are gone
    with sqlite3.connect(tmp_path / "results.db") as db:
        before = db.execute("SELECT id, planner, run, time FROM runs ORDER BY id").fetchall()
    assert len(before) == 1

    given = []
    call = RayBackend.__call__

    def recording(self, config, jobs):
        given.append(list(jobs))
        yield from call(self, config, jobs)

    monkeypatch.setattr(RayBackend, "__call__", recording)
    evaluate_on_ray(QUICK, tmp_path, progress=False)
    assert len(given[0]) == 2 and not {(p, r) for _, p, r in given[0]} & {(p, r) for _, p, r, _ in before}
    with sqlite3.connect(tmp_path / "results.db") as db:
        after = db.execute("SELECT id, planner, run, time FROM runs ORDER BY id").fetchall()
    assert after[:1] == before and len(after) == 3  # the stored run kept, not run again
    rows = _rows(tmp_path / "results.db")
    _same_rows(rows[:2], [r for r in pool_rows[1] if r["planner"] == "ompl-rrtconnect"])
    assert rows[2]["run"] == 2 and rows[2]["seed"] == 2


def test_a_ray_evaluation_resumes_a_store_the_pool_filled(local_ray, pool_rows, tmp_path, monkeypatch):
    shutil.copy(pool_rows[0] / "results.db", tmp_path / "results.db")
    with sqlite3.connect(tmp_path / "results.db") as db:
        db.execute("DELETE FROM runs WHERE planner = 'ompl-rrtconnect' AND run = 1")
        kept = db.execute("SELECT * FROM runs ORDER BY id").fetchall()
    store = ResultsStore(tmp_path / "results.db")
    assert runner.pending_jobs(CONFIG, store.done()) == [("exp1", "ompl-rrtconnect", 1)]
    store.close()
    given = []
    call = RayBackend.__call__
    monkeypatch.setattr(RayBackend, "__call__", lambda self, config, jobs: given.append(jobs) or call(self, config, jobs))
    evaluate_on_ray(CONFIG, tmp_path, progress=False)
    assert given == [[("exp1", "ompl-rrtconnect", 1)]]
    with sqlite3.connect(tmp_path / "results.db") as db:
        assert db.execute("SELECT * FROM runs ORDER BY id").fetchall()[:3] == kept
    _same_rows(_rows(tmp_path / "results.db"), pool_rows[1])


class StandInActor(RunActor):
    """No PyBullet: run 1 does not return for a minute (nor lets an alarm stop it), run 2
    kills its process, the others succeed at once."""

    def run(self, job):
        experiment, planner, run = job
        if run == 1:
            deadline = time.monotonic() + 60
            while time.monotonic() < deadline:
                time.sleep(0.05)
        if run == 2:
            os._exit(1)
        record = runner.crash_record(planner, experiment, runner.run_seed(experiment, run), "")
        record.outcome, record.success, record.path_length = "success", True, 0.5
        return job, "ur5", record


def test_a_stuck_run_and_a_dying_actor_become_crash_records(local_ray, tmp_path, monkeypatch):
    monkeypatch.setattr(ray_runner, "RunActor", StandInActor)
    monkeypatch.setattr(ray_runner, "STUCK_GRACE", 0.5)
    config = EvaluationConfig(("exp1",), ("rrt",), runs=4, workers=2, run_timeout=1.0)
    start = time.monotonic()
    evaluate_on_ray(config, tmp_path, progress=False)
    assert time.monotonic() - start < 60
    rows = _rows(tmp_path / "results.db")
    assert [(r["run"], r["status"]) for r in rows] == [(0, "success"), (1, "crash"), (2, "crash"), (3, "success")]
    assert "exceeded 1 s" in rows[1]["message"] and "actor was killed" in rows[1]["message"]
    assert "died 2 times" in rows[2]["message"]  # given to a fresh actor once, then stored


class HangingPlanner(GlobalPlanner):
    """RRT that hangs while ``hang`` is set: the alarm of ``Worker.run`` must stop it."""

    name = "rrt"
    hang = False

    def __init__(self, inner):
        self.inner = inner

    def plan(self, checker, q_start, q_goal, rng):
        if self.hang:
            time.sleep(120)
        return self.inner.plan(checker, q_start, q_goal, rng)

    def config(self):
        return self.inner.config()


class AlarmActor(RunActor):
    """A real Worker, in a Ray actor's process, whose planner hangs on run 0; its world is
    built and its planner run once (compiling its kernels) before, so that the alarm times
    only the runs."""

    def __init__(self, config):
        make = runner.make_planner
        runner.make_planner = lambda *a, **k: HangingPlanner(make(*a, **k))
        super().__init__(config)
        executor = self.worker.executor("exp1")
        self.planner = self.worker.planner("rrt", executor.robot)
        executor.run(self.planner, 1)

    def run(self, job):
        self.planner.hang = job[2] == 0
        return super().run(job)


def test_an_overrunning_run_is_stopped_by_the_workers_alarm_in_a_ray_actor(local_ray, tmp_path, monkeypatch):
    """The pool's timeout, in the actor: the driver's backstop is not what stops it here."""
    monkeypatch.setattr(ray_runner, "RunActor", AlarmActor)
    monkeypatch.setattr(ray_runner, "STUCK_GRACE", 600.0)
    config = EvaluationConfig(("exp1",), ("rrt",), runs=2, workers=1, run_timeout=5.0)
    evaluate_on_ray(config, tmp_path, actors=1, progress=False)
    rows = _rows(tmp_path / "results.db")
    assert [r["status"] for r in rows] == ["crash", "success"], [r["message"] for r in rows]
    assert rows[0]["message"] == "RunTimeout: run exceeded 5 s"  # the pool's message


def test_importing_the_evaluation_and_the_sweep_does_not_import_ray():
    code = ("import sys, rayreach.evaluate, rayreach.evaluate.ray_runner, rayreach.learning.sweep, rayreach.cli; "
            "rayreach.cli.build_parser(); assert 'ray' not in sys.modules, 'ray was imported'")
    subprocess.run([sys.executable, "-c", code], check=True, timeout=120)


@pytest.mark.parametrize("argv", [
    ["evaluate", "--experiments", "1", "--planners", "rrt", "--runs", "1", "--ray"],
    ["evaluate", "--experiments", "1", "--planners", "rrt", "--runs", "1", "--ray", "auto"],
    ["sweep", "--robot", "ur5", "--seeds", "0", "--ray"],
])
def test_ray_options_without_ray_say_how_to_install_it(tmp_path, monkeypatch, capsys, argv):
    from rayreach.cli import main

    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` raises ImportError
    assert main([*argv, "--out", str(tmp_path / "out")]) == 2
    assert "pip install rayreach[ray]" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()  # refused before anything ran
    with pytest.raises(ImportError, match=r"rayreach\[ray\]"):
        ray_runner.import_ray()


def test_evaluate_ray_option_reaches_the_ray_runner(tmp_path, monkeypatch):
    from rayreach.cli import main

    seen = []
    monkeypatch.setattr(ray_runner, "evaluate_on_ray", lambda config, out, address, actors: seen.append(
        (address, actors, config.planners)))
    (tmp_path / "table.md").write_text("| table |")
    monkeypatch.setattr("rayreach.evaluate.write_report", lambda out: {"table": tmp_path / "table.md"})
    base = ["evaluate", "--experiments", "1", "--planners", "rrt", "--runs", "1", "--out", str(tmp_path)]
    main([*base, "--ray"])
    main([*base, "--ray", "ray://head:10001", "--workers", "8"])
    assert seen == [(None, None, ("rrt",)), ("ray://head:10001", 8, ("rrt",))]


# ---------------------------------------------------------------------- sweeps
BASE = replace(with_envs(TrainConfig(), 4), workers=1, max_episode_steps=32, checkpoint_every=10**9, timesteps=256)
"""The default recipe on 4 worlds: one 256-step rollout."""


def test_a_sweep_plans_one_directory_per_seed_or_per_value_and_seed(tmp_path):
    trials = sweeps.plan_trials(BASE, tmp_path, seeds=sweeps.parse_seeds("0,1-2"))
    assert [(t.name, t.out, t.config.seed) for t in trials] == [
        (f"seed-{s}", tmp_path / f"seed-{s}", s) for s in (0, 1, 2)]
    setting = sweeps.parse_setting("learning_rate=3e-4,1e-3", BASE)
    assert setting == ("learning_rate", (3e-4, 1e-3))
    trials = sweeps.plan_trials(BASE, tmp_path, seeds=(0, 1), setting=setting)
    assert [t.name for t in trials] == ["learning_rate-0.0003-seed-0", "learning_rate-0.0003-seed-1",
                                        "learning_rate-0.001-seed-0", "learning_rate-0.001-seed-1"]
    assert [(t.config.learning_rate, t.config.seed) for t in trials] == [(3e-4, 0), (3e-4, 1), (1e-3, 0), (1e-3, 1)]
    assert all(replace(t.config, learning_rate=BASE.learning_rate, seed=0) == BASE for t in trials)
    assert sweeps.parse_setting("target_kl=none,0.05", BASE) == ("target_kl", (None, 0.05))
    assert sweeps.parse_setting("acting_layers=true", BASE) == ("acting_layers", (True,))
    envs = sweeps.plan_trials(TrainConfig(), tmp_path, setting=sweeps.parse_setting("envs=8", TrainConfig()))
    assert (envs[0].config.envs, envs[0].config.batch_size) == (8, 8 * 64)  # as --envs: the minibatch fits
    for text, message in (("seed=1,2", "--seeds"), ("lr=1", "no field 'lr'"), ("goal=1", "cannot be swept"),
                          ("n_epochs=two", "not a int"), ("learning_rate", "FIELD=V1,V2")):
        with pytest.raises(ValueError, match=message):
            sweeps.parse_setting(text, BASE)
    with pytest.raises(ValueError, match="0,1,2"):
        sweeps.parse_seeds("a")


def _bundle(path: Path, kind: str, steps: int) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr(META_ENTRY, json.dumps({"format": FORMAT, "kind": kind, "timesteps": steps}))
        archive.writestr("policy.pth", b"")


def stand_in_train(config, out, resume=False, command=""):
    """Stands for ``train``: logs its call in the run directory, writes a checkpoint and a
    model of ``config.timesteps``; seed 1 stops after its checkpoint as an interrupt does."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    with (out / "calls.jsonl").open("a") as handle:
        handle.write(json.dumps({"resume": resume, "seed": config.seed, "workers": config.workers,
                                 "pid": os.getpid()}) + "\n")
    _bundle(out / "checkpoint.zip", "checkpoint", config.timesteps // 2)
    if config.seed == 1 and not resume:
        raise KeyboardInterrupt("interrupted; resume with --resume")
    _bundle(out / "model.zip", "model", config.timesteps)
    return out / "model.zip"


def _calls(trial_dir: Path) -> list[dict]:
    path = trial_dir / "calls.jsonl"
    return [json.loads(line) for line in path.read_text().splitlines()] if path.exists() else []


def test_an_interrupted_sweep_resumes_each_trial_from_what_its_directory_holds(local_ray, tmp_path):
    trials = sweeps.plan_trials(BASE, tmp_path, seeds=(0, 1, 2))
    with pytest.raises(KeyboardInterrupt):
        sweeps.sweep(trials, train_fn=stand_in_train)  # here, one after another: stops at seed 1
    assert [sweeps.trial_state(t) for t in trials] == ["done", "resume", "new"]

    results = sweeps.sweep(trials, use_ray=True, cpus=1, train_fn=stand_in_train)  # on the module's Ray
    assert [(r.trial.name, r.state, r.error) for r in results] == [
        ("seed-0", "done", None), ("seed-1", "resume", None), ("seed-2", "new", None)]
    assert all(r.model == r.trial.out / "model.zip" for r in results)
    assert [c["resume"] for c in _calls(tmp_path / "seed-0")] == [False]  # done: not trained again
    assert [c["resume"] for c in _calls(tmp_path / "seed-1")] == [False, True]
    ray_calls = _calls(tmp_path / "seed-1")[1:] + _calls(tmp_path / "seed-2")
    assert all(c["workers"] == 1 and c["pid"] != os.getpid() for c in ray_calls)  # Ray tasks of --cpus workers
    more = [replace(t, config=replace(t.config, timesteps=512)) for t in trials]
    assert [sweeps.trial_state(t) for t in more] == ["resume"] * 3  # more steps asked: each goes on


def test_a_failing_trial_is_reported_and_the_others_run(tmp_path):
    def failing(config, out, resume=False, command=""):
        if config.seed == 0:
            raise ValueError("bad setting")
        return stand_in_train(config, out, resume, command)

    reported = []
    results = sweeps.sweep(sweeps.plan_trials(BASE, tmp_path, seeds=(0, 2)), train_fn=failing,
                           report=reported.append)
    assert [(r.trial.name, r.error) for r in results] == [("seed-0", "ValueError: bad setting"), ("seed-2", None)]
    assert reported == results


def test_the_sweep_command_trains_tiny_trials_and_resumes_them(tmp_path, capsys, monkeypatch):
    """The real ``train``: a 256-step run per trial, then 512 steps resumed from the checkpoints."""
    from rayreach.cli import main
    from rayreach.learning.bundles import read_bundle_meta
    from rayreach.learning import train as training

    monkeypatch.setitem(training.RECIPES, "default", replace(BASE, checkpoint_every=100_000))
    argv = ["sweep", "--robot", "ur5", "--seeds", "0", "--set", "n_epochs=1,2", "--timesteps", "256",
            "--out", str(tmp_path)]
    assert main(argv) == 0
    names = ["n_epochs-1-seed-0", "n_epochs-2-seed-0"]
    for name, epochs in zip(names, (1, 2)):
        meta, _ = read_bundle_meta(tmp_path / name / "model.zip")
        assert meta["timesteps"] == 256 and meta["config"]["n_epochs"] == epochs and meta["config"]["seed"] == 0
    assert main(argv) == 0
    assert "n_epochs-1-seed-0 (done)" in capsys.readouterr().out
    assert main([*argv[:-3], "512", "--out", str(tmp_path)]) == 0
    assert "n_epochs-2-seed-0 (resume)" in capsys.readouterr().out
    meta, _ = read_bundle_meta(tmp_path / names[1] / "model.zip")
    assert meta["timesteps"] == 512 and meta["config"]["n_epochs"] == 2
