"""Evaluation: resumable runs in SQLite, failures recorded not fatal, report files."""

from __future__ import annotations

import sqlite3
import subprocess
import sys
import time

import numpy as np
import pytest

from rayreach.evaluate import EvaluationConfig, evaluate, parse_experiments, write_report
from rayreach.evaluate import runner
from rayreach.evaluate.executor import Executor
from rayreach.evaluate.report import markdown_table, summarise
from rayreach.evaluate.store import SCHEMA, ResultsStore
from rayreach.planners import make_planner
from rayreach.planners.base import GlobalPlanner

SMALL = EvaluationConfig(("exp1",), ("birrt", "ncrrt"), runs=3, workers=1)


def _stored(path) -> list[tuple]:
    with sqlite3.connect(path) as db:
        return db.execute("SELECT e.name, r.planner, r.run, r.seed, r.status, round(r.solution_length, 9) "
                          "FROM runs r JOIN experiments e ON e.id = r.experimentid "
                          "ORDER BY e.name, r.planner, r.run").fetchall()


def test_parse_experiments_accepts_ranges_lists_and_names():
    assert parse_experiments("1-3") == ("exp1", "exp2", "exp3")
    assert parse_experiments("exp4,1,exp4") == ("exp4", "exp1")
    assert parse_experiments("random-ur5") == ("random-ur5",)
    with pytest.raises(ValueError, match="exp1, exp2"):
        parse_experiments("9")


def test_random_experiment_names_carry_their_obstacle_count_and_split():
    assert runner.random_experiment("kr16") == "random-kr16@test"
    assert runner.random_experiment("kr16", 1, "validation") == "random-kr16:1@validation"
    assert runner.parse_random("random-kr16@test", 3) == runner.RandomExperiment("kr16", 3, "test")
    assert runner.parse_random("random-kr16:1@validation", 3) == runner.RandomExperiment("kr16", 1, "validation")
    with pytest.raises(ValueError, match="whole number"):
        runner.parse_random("random-ur5:-1@test", 3)
    with pytest.raises(ValueError, match="valid: validation, test"):
        runner.parse_random("random-ur5@train", 3)
    with pytest.raises(ValueError, match="valid: validation, test"):
        runner.random_experiment("ur5", split="train")
    with pytest.raises(ValueError, match="known: kr16, ur10, ur5"):
        EvaluationConfig(("random-abb:2@test",), ("drl",))


def test_old_random_names_without_a_split_are_the_validation_range():
    """Databases from before names carried the split drew from seed 1,000,000 on."""
    assert runner.parse_random("random-kr16", 3) == runner.RandomExperiment("kr16", 3, "validation")
    assert runner.parse_random("random-kr16:1", 3) == runner.RandomExperiment("kr16", 1, "validation")
    for run in (0, 7):
        assert runner.run_seed("random-ur5:2", run) == runner.run_seed("random-ur5:2@validation", run) == 1_000_000 + run
        assert runner.run_seed("random-ur5@test", run) == 9_000_000 + run
        assert runner.run_seed("exp1", run) == run


def test_a_random_experiment_with_a_count_plays_the_rollout_worlds_of_that_count():
    """``random-ur5:2`` (validation) run r is rollout's world of seed 1,000,000 + r with 2
    obstacles, so the two commands measure the same worlds."""
    from rayreach.env.reach import ReachEnv

    worker = runner.Worker(EvaluationConfig(("random-ur5:2",), ("drl",), runs=1, workers=1))
    env = ReachEnv(robot="ur5", scenario="random")
    try:
        env.set_n_obstacles(2)
        ex = worker.executor("random-ur5:2")
        assert ex.env.n_obstacles == 2 and worker.executor("random-ur5").env.n_obstacles == 3
        for run in range(3):
            ex.reset(runner.run_seed("random-ur5:2", run))
            env.reset(seed=1_000_000 + run)
            assert [o.name for o in ex.env.scenario.obstacles] == [o.name for o in env.scenario.obstacles]
            np.testing.assert_array_equal(ex.env.goals, env.goals)
    finally:
        worker.close()
        env.close()


def test_a_broad_experiment_plays_the_broad_worlds_of_its_split():
    from rayreach.scenarios.broad_world import broad_kinds, broad_workspace

    assert runner.random_experiment("ur5", 2, "test", "broad") == "broad-ur5:2@test"
    assert runner.parse_random("broad-ur5:2@test", 3) == runner.RandomExperiment("ur5", 2, "test", "broad")
    assert parse_experiments("broad-kr16@validation,exp1") == ("broad-kr16@validation", "exp1")
    assert runner.run_seed("broad-ur5@test", 4) == 9_000_004
    with pytest.raises(ValueError, match="random, broad"):
        runner.random_experiment("ur5", 2, "test", "wide")
    worker = runner.Worker(EvaluationConfig(("broad-ur5:2@test",), ("drl-alone",), runs=1, workers=1))
    try:
        ex = worker.executor("broad-ur5:2@test")
        ex.reset(runner.run_seed("broad-ur5:2@test", 0))
        assert len(broad_kinds(ex.env.scenario)) == 2 and ex.env.scenario.name == "broad"
        low, high = broad_workspace(ex.env.spec_robot)
        np.testing.assert_array_equal(ex.env.scenario.workspace_low, low)
        assert ex.env.observation_space.shape == (142,)
    finally:
        worker.close()


def test_unknown_planner_is_refused_with_the_valid_names():
    with pytest.raises(ValueError, match="ompl-rrtconnect"):
        EvaluationConfig(("exp1",), ("prm",))


@pytest.fixture(scope="module")
def full_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("full")
    evaluate(SMALL, out, progress=False)
    return out


def test_a_killed_evaluation_resumes_to_the_same_results(full_run, tmp_path):
    out = tmp_path / "killed"
    command = [sys.executable, "-m", "rayreach.cli", "evaluate", "--experiments", "1", "--planners", "birrt,ncrrt",
               "--runs", "3", "--workers", "1", "--out", str(out)]
    proc = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 240  # a loaded 2-core machine takes long to import the stack
    while time.monotonic() < deadline and proc.poll() is None:
        if (out / "results.db").exists() and len(_stored(out / "results.db")) >= 2:
            break
        time.sleep(0.05)
    proc.kill()
    proc.wait()
    interrupted = len(_stored(out / "results.db"))
    assert 2 <= interrupted
    subprocess.run(command, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=300)
    assert _stored(out / "results.db") == _stored(full_run / "results.db")
    assert len(_stored(out / "results.db")) == 6


def test_rerunning_a_finished_evaluation_runs_nothing(full_run, monkeypatch):
    before = _stored(full_run / "results.db")
    monkeypatch.setattr(runner.Worker, "run", lambda *a: pytest.fail("a finished run was run again"))
    evaluate(SMALL, full_run, progress=False)
    assert _stored(full_run / "results.db") == before


class Flaky(GlobalPlanner):
    """Raises on run seed 1, hangs on seed 2: both must become crash records."""

    name = "birrt"

    def __init__(self) -> None:
        self.inner = make_planner("birrt", "ur5")
        self.calls = 0

    def plan(self, checker, q_start, q_goal, rng):
        self.calls += 1
        if self.calls == 2:
            raise RuntimeError("planner exploded")
        if self.calls == 3:
            time.sleep(30)
        return self.inner.plan(checker, q_start, q_goal, rng)

    def config(self):
        return self.inner.config()


def test_a_planner_that_raises_or_hangs_is_recorded_and_the_evaluation_goes_on(tmp_path, monkeypatch):
    flaky = Flaky()
    monkeypatch.setattr(runner, "make_planner", lambda *a, **k: flaky)
    # the limit leaves a real run room on a loaded machine; the hanging one sleeps far past it
    config = EvaluationConfig(("exp1",), ("birrt",), runs=4, workers=1, run_timeout=5.0)
    evaluate(config, tmp_path, progress=False)
    store = ResultsStore(tmp_path / "results.db")
    rows = store.rows()
    store.close()
    assert [r["status"] for r in rows] == ["success", "crash", "crash", "success"]
    assert "planner exploded" in rows[1]["message"] and "exceeded 5 s" in rows[2]["message"]


def test_report_writes_table_csv_and_figures(full_run):
    written = write_report(full_run)
    for key in ("csv", "table", "bars", "trajectories_ur5"):
        assert written[key].exists() and written[key].stat().st_size > 0
    table = written["table"].read_text()
    assert "| exp1 |" in table and "paper DRL" in table and "3/3 (0 coll.)" in table
    assert len(written["csv"].read_text().splitlines()) == 7


def test_table_means_are_over_successes_and_best_is_bold():
    rows = [
        {"experiment": "exp1", "planner": "rrt", "solved": 1, "collision": 0, "status": "success",
         "execution_time": 2.0, "solution_length": 1.0, "time": 0.5},
        {"experiment": "exp1", "planner": "rrt", "solved": 1, "collision": 0, "status": "success",
         "execution_time": 4.0, "solution_length": 3.0, "time": 0.5},
        {"experiment": "exp1", "planner": "rrt", "solved": 0, "collision": 1, "status": "collision",
         "execution_time": 99.0, "solution_length": 99.0, "time": 0.5},
        {"experiment": "exp1", "planner": "ncrrt", "solved": 0, "collision": 0, "status": "no plan",
         "execution_time": 0.0, "solution_length": None, "time": 30.0},
    ]
    stats = summarise(rows)
    assert stats[("exp1", "rrt")]["execution_time"] == (3.0, 1.0)
    assert stats[("exp1", "ncrrt")]["execution_time"] is None
    table = markdown_table(rows)
    assert "**3.00 ± 1.00**" in table and "| exp1 | / | **" not in table
    assert "2/3 (1 coll.)" in table and "0/1 (0 coll.)" in table
    random_only = markdown_table([{**r, "experiment": "random-ur5"} for r in rows])
    assert "| experiment | rrt | ncrrt |\n" in random_only  # no empty paper columns


def test_evaluate_refuses_an_obstacle_count_outside_the_random_suite(tmp_path, capsys):
    from rayreach.cli import main

    assert main(["evaluate", "--experiments", "1", "--obstacles", "2", "--out", str(tmp_path)]) == 2
    assert "--suite random or broad" in capsys.readouterr().err


class FakeExecutor:
    """Stands for an Executor in the cache tests: no PyBullet world, counts the open ones."""

    open: set[str] = set()
    built: list[str] = []

    def __init__(self, scenario, robot=None, config=None) -> None:
        self.name = str(scenario)
        self.robot = "ur5"
        FakeExecutor.built.append(self.name)
        FakeExecutor.open.add(self.name)
        assert len(FakeExecutor.open) <= runner.EXECUTORS_KEPT, "a worker held more executors than it keeps"

    def run(self, planner, seed):
        return runner.crash_record("birrt", self.name, seed, "fake")

    def close(self) -> None:
        FakeExecutor.open.remove(self.name)


@pytest.fixture
def fake_executors(monkeypatch):
    FakeExecutor.open, FakeExecutor.built = set(), []
    monkeypatch.setattr(runner, "Executor", FakeExecutor)
    monkeypatch.setattr(runner, "make_planner", lambda *a, **k: None)
    return FakeExecutor


def test_a_worker_keeps_the_most_recently_used_executors_and_closes_the_rest(fake_executors):
    worker = runner.Worker(SMALL, keep=2)
    for name in ("exp1", "exp2", "exp1", "exp3", "exp1", "exp2"):
        worker.executor(name)
    assert fake_executors.built == ["exp1", "exp2", "exp3", "exp2"]  # exp2 was evicted by exp3, exp3 by exp2
    assert list(worker.executors) == ["exp1", "exp2"] and fake_executors.open == {"exp1", "exp2"}
    worker.close()
    assert fake_executors.open == set()
    with pytest.raises(ValueError, match="at least 1"):
        runner.Worker(SMALL, keep=0)


def test_an_evaluation_over_more_scenes_than_the_cache_closes_executors(fake_executors, tmp_path):
    scenes = tuple(f"exp{i}" for i in range(1, 8))
    evaluate(EvaluationConfig(scenes, ("birrt",), runs=2, workers=1), tmp_path, progress=False)
    assert fake_executors.built == list(scenes) and fake_executors.open == set()
    assert len(_stored(tmp_path / "results.db")) == 14


def test_sampling_planners_run_on_random_worlds_of_the_test_split():
    with Executor("random", robot="ur5") as ex:
        for name in ("birrt", "ncrrt"):
            record = ex.run(make_planner(name, "ur5", time_limit=2.0), runner.run_seed("random-ur5@test", 0))
            assert record.seed == 9_000_000 and record.outcome != "crash" and record.acting_share == {}


def test_evaluate_random_stores_the_split_in_the_name_and_takes_any_planner(tmp_path):
    from rayreach.cli import main

    assert main(["evaluate", "--suite", "random", "--robot", "ur5", "--episodes", "1", "--planners", "birrt",
                 "--workers", "1", "--time-limit", "2", "--out", str(tmp_path)]) == 0
    assert [row[:4] for row in _stored(tmp_path / "results.db")] == [("random-ur5@test", "birrt", 0, 9_000_000)]


@pytest.mark.parametrize("argv, experiments, planners", [
    ([], ("random-ur5@test",), ("drl", "drl-alone")),
    (["--split", "validation", "--obstacles", "2"], ("random-ur5:2@validation",), ("drl", "drl-alone")),
    (["--planners", "drl,drl-alone,rrt"], ("random-ur5@test",), ("drl", "drl-alone", "rrt")),
])
def test_evaluate_random_defaults_to_the_test_split_and_the_policy_with_and_without_its_layers(
        tmp_path, monkeypatch, argv, experiments, planners):
    import rayreach.evaluate as evaluate_package
    from rayreach.cli import main

    seen = []
    monkeypatch.setattr(evaluate_package, "evaluate", lambda config, out: seen.append(config))
    main(["evaluate", "--suite", "random", "--robot", "ur5", "--episodes", "1", "--out", str(tmp_path), *argv])
    assert seen[0].experiments == experiments and seen[0].planners == planners


def test_evaluate_refuses_a_split_outside_the_random_suite(tmp_path, capsys):
    from rayreach.cli import main

    assert main(["evaluate", "--experiments", "1", "--split", "test", "--out", str(tmp_path)]) == 2
    assert "--split applies to --suite random" in capsys.readouterr().err


OLD_RUNS = SCHEMA.replace("    acting_share TEXT,\n", "")


def test_an_old_database_without_acting_shares_opens_and_is_migrated(tmp_path):
    path = tmp_path / "results.db"
    assert "acting_share" not in OLD_RUNS
    with sqlite3.connect(path) as db:
        db.executescript(OLD_RUNS)
        db.execute("INSERT INTO experiments (name, robot, goal_tolerance) VALUES ('random-ur5', 'ur5', 0.01)")
        db.execute("INSERT INTO plannerConfigs (name, settings) VALUES ('drl', '{}')")
        db.execute("INSERT INTO runs (experimentid, plannerid, planner, run, seed, status, plan_status, solved, "
                   "collision, time, motion_time, execution_time, steps, replans, versions) "
                   "VALUES (1, 1, 'drl', 0, 1000000, 'success', 'solved', 1, 0, 0.1, 1.0, 1.1, 50, 0, '{}')")
    store = ResultsStore(path)
    record = runner.crash_record("drl", "random", 1_000_001, "")
    record.acting_share = {"policy": 0.75, "final_approach": 0.25}
    store.add("random-ur5", "ur5", 0.01, 1, record, {}, None)
    rows = store.rows()
    store.close()
    assert [r["acting_share"] for r in rows] == [{}, {"policy": 0.75, "final_approach": 0.25}]
    ResultsStore(path).close()  # a second opening finds the column there
