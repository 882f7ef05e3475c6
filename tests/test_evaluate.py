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
from rayreach.evaluate.report import box_edges, markdown_table, resample, summarise
from rayreach.evaluate.store import ResultsStore
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


def test_random_experiment_names_carry_their_obstacle_count():
    assert runner.random_experiment("kr16") == "random-kr16"
    assert runner.random_experiment("kr16", 1) == "random-kr16:1"
    assert runner.parse_random("random-kr16", 3) == ("kr16", 3)
    assert runner.parse_random("random-kr16:1", 3) == ("kr16", 1)
    with pytest.raises(ValueError, match="whole number"):
        runner.parse_random("random-ur5:-1", 3)
    with pytest.raises(ValueError, match="known: kr16, ur5"):
        EvaluationConfig(("random-abb:2",), ("drl",))


def test_a_random_experiment_with_a_count_plays_the_rollout_worlds_of_that_count():
    """``random-ur5:2`` run r is rollout's world of seed 1,000,000 + r with 2 obstacles,
    so the two commands measure the same worlds."""
    from rayreach.env import ReachEnv

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
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline:
        if (out / "results.db").exists() and len(_stored(out / "results.db")) >= 2:
            break
        time.sleep(0.05)
    proc.kill()
    proc.wait()
    interrupted = len(_stored(out / "results.db"))
    assert 2 <= interrupted
    subprocess.run(command, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=120)
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
    config = EvaluationConfig(("exp1",), ("birrt",), runs=4, workers=1, run_timeout=1.0)
    evaluate(config, tmp_path, progress=False)
    store = ResultsStore(tmp_path / "results.db")
    rows = store.rows()
    store.close()
    assert [r["status"] for r in rows] == ["success", "crash", "crash", "success"]
    assert "planner exploded" in rows[1]["message"] and "exceeded 1 s" in rows[2]["message"]


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


def test_resample_is_even_in_arc_length():
    points = np.array([[0.0, 0, 0], [1.0, 0, 0], [1.0, 3.0, 0]])
    r = resample(points, 5)
    np.testing.assert_allclose(r[[0, -1]], points[[0, -1]])
    np.testing.assert_allclose(np.linalg.norm(np.diff(r, axis=0), axis=1), 1.0)


def test_box_edges_follow_pybullets_pose_of_a_rotated_box():
    """The plotted edges of a box with roll, pitch and yaw end at the corners PyBullet places
    for the same pose, and each is as long as the box's side along that axis."""
    import pybullet as pb

    centre, half, rpy = (0.4, -0.1, 0.3), (0.05, 0.1, 0.002), (0.3, -0.2, 1.1)
    quat = pb.getQuaternionFromEuler(rpy)
    expected = np.array([pb.multiplyTransforms(centre, quat, (sx * half[0], sy * half[1], sz * half[2]),
                                               (0, 0, 0, 1))[0]
                         for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    edges = box_edges(centre, half, rpy)
    assert len(edges) == 12
    ends = np.unique(np.round([p for edge in edges for p in edge], 9), axis=0)
    assert len(ends) == 8
    nearest = np.linalg.norm(ends[:, None] - expected[None], axis=2)  # PyBullet computes in float32
    assert np.all(nearest.min(axis=1) < 1e-6) and len(set(nearest.argmin(axis=1))) == 8
    lengths = sorted(round(float(np.linalg.norm(a - b)), 9) for a, b in edges)
    assert lengths == sorted([2 * h for h in half for _ in range(4)])


def test_evaluate_refuses_an_obstacle_count_outside_the_random_suite(tmp_path, capsys):
    from rayreach.cli import main

    assert main(["evaluate", "--experiments", "1", "--obstacles", "2", "--out", str(tmp_path)]) == 2
    assert "--suite random" in capsys.readouterr().err
