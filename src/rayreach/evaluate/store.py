"""The results database: one SQLite file per evaluation, every finished run stored at once.

The layout follows OMPL's benchmark database (tables ``experiments``, ``plannerConfigs``,
``runs`` with ``time``, ``solved``, ``solution_length``, ``status``), which Planner Arena
reads, plus rayreach's own columns. Schema and column meanings: ``docs/metrics.md``.
"""

from __future__ import annotations

import io
import json
import sqlite3
from pathlib import Path
from typing import Any, Iterator

import numpy as np

from rayreach.evaluate.executor import RunRecord

SCHEMA = """
CREATE TABLE IF NOT EXISTS experiments (
    id INTEGER PRIMARY KEY,
    name TEXT UNIQUE NOT NULL,
    robot TEXT NOT NULL,
    goal_tolerance REAL NOT NULL
);
CREATE TABLE IF NOT EXISTS plannerConfigs (
    id INTEGER PRIMARY KEY,
    name TEXT NOT NULL,
    settings TEXT NOT NULL,
    UNIQUE (name, settings)
);
CREATE TABLE IF NOT EXISTS runs (
    id INTEGER PRIMARY KEY,
    experimentid INTEGER NOT NULL REFERENCES experiments (id),
    plannerid INTEGER NOT NULL REFERENCES plannerConfigs (id),
    planner TEXT NOT NULL,
    run INTEGER NOT NULL,
    seed INTEGER NOT NULL,
    status TEXT NOT NULL,
    plan_status TEXT NOT NULL,
    solved INTEGER NOT NULL,
    collision INTEGER NOT NULL,
    solution_length REAL,
    solution_length_unsmoothed REAL,
    joint_path_length REAL,
    time REAL NOT NULL,
    motion_time REAL NOT NULL,
    execution_time REAL NOT NULL,
    steps INTEGER NOT NULL,
    replans INTEGER NOT NULL,
    message TEXT,
    acting_share TEXT,
    ee_path BLOB,
    versions TEXT NOT NULL,
    git_commit TEXT,
    UNIQUE (experimentid, planner, run)
);
"""

COLUMNS = ("experiment", "planner", "run", "seed", "status", "plan_status", "solved", "collision",
           "solution_length", "solution_length_unsmoothed", "joint_path_length", "time", "motion_time",
           "execution_time", "steps", "replans", "message", "acting_share", "git_commit")
"""The columns of ``runs.csv`` and :meth:`ResultsStore.rows` (``time`` is the planning time;
``acting_share``: a dict, empty for global planners and for runs stored before it was kept)."""

ADDED_COLUMNS = {"acting_share": "TEXT"}
"""Columns of ``runs`` newer than the first databases, added to an old file when it is opened."""


def _nan_to_none(x: float) -> float | None:
    return None if x != x else float(x)


def _encode_path(points: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    np.save(buffer, np.asarray(points, dtype=np.float32))
    return buffer.getvalue()


def decode_path(blob: bytes | None) -> np.ndarray:
    return np.load(io.BytesIO(blob)) if blob else np.zeros((0, 3), dtype=np.float32)


class ResultsStore:
    """Open (or create) ``path``; a corrupt file raises an error that names it."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        try:
            self.db = sqlite3.connect(self.path)
            self.db.executescript(SCHEMA)
            self._migrate()
        except sqlite3.DatabaseError as exc:
            raise ValueError(f"{self.path} is not a rayreach results database ({exc}); move it away or "
                             "choose another --out") from exc

    def _migrate(self) -> None:
        """Add the :data:`ADDED_COLUMNS` an older database lacks (its rows get NULL there)."""
        present = {row[1] for row in self.db.execute("PRAGMA table_info(runs)")}
        for name, kind in ADDED_COLUMNS.items():
            if name not in present:
                self.db.execute(f"ALTER TABLE runs ADD COLUMN {name} {kind}")
        self.db.commit()

    def close(self) -> None:
        self.db.close()

    def experiment_id(self, name: str, robot: str, goal_tolerance: float) -> int:
        self.db.execute("INSERT OR IGNORE INTO experiments (name, robot, goal_tolerance) VALUES (?, ?, ?)",
                        (name, robot, goal_tolerance))
        return int(self.db.execute("SELECT id FROM experiments WHERE name = ?", (name,)).fetchone()[0])

    def planner_id(self, name: str, settings: dict[str, Any]) -> int:
        text = json.dumps(settings, sort_keys=True, default=str)
        self.db.execute("INSERT OR IGNORE INTO plannerConfigs (name, settings) VALUES (?, ?)", (name, text))
        row = self.db.execute("SELECT id FROM plannerConfigs WHERE name = ? AND settings = ?", (name, text)).fetchone()
        return int(row[0])

    def done(self) -> set[tuple[str, str, int]]:
        """(experiment, planner, run) of every stored run."""
        rows = self.db.execute("SELECT e.name, r.planner, r.run FROM runs r JOIN experiments e ON e.id = r.experimentid")
        return {(e, p, int(r)) for e, p, r in rows}

    def add(self, experiment: str, robot: str, goal_tolerance: float, run: int, record: RunRecord,
            versions: dict[str, str], git_commit: str | None) -> None:
        """Store one finished run and commit at once (an interrupt loses nothing stored)."""
        eid = self.experiment_id(experiment, robot, goal_tolerance)
        pid = self.planner_id(record.planner, record.config)
        self.db.execute(
            "INSERT OR REPLACE INTO runs (experimentid, plannerid, planner, run, seed, status, plan_status, solved, "
            "collision, solution_length, solution_length_unsmoothed, joint_path_length, time, motion_time, "
            "execution_time, steps, replans, message, acting_share, ee_path, versions, git_commit) "
            "VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
            (eid, pid, record.planner, run, record.seed, record.outcome, record.plan_status, int(record.success),
             int(record.collision), _nan_to_none(record.path_length), _nan_to_none(record.path_length_unsmoothed),
             _nan_to_none(record.joint_path_length), record.planning_time, record.motion_time,
             record.execution_time, record.steps, record.replans, record.message,
             json.dumps(record.acting_share, sort_keys=True), _encode_path(record.ee_path),
             json.dumps(versions, sort_keys=True), git_commit))
        self.db.commit()

    def rows(self) -> list[dict[str, Any]]:
        """Every run as a dict of :data:`COLUMNS`, ordered by experiment, planner and run."""
        cursor = self.db.execute(
            "SELECT e.name, r.planner, r.run, r.seed, r.status, r.plan_status, r.solved, r.collision, "
            "r.solution_length, r.solution_length_unsmoothed, r.joint_path_length, r.time, r.motion_time, "
            "r.execution_time, r.steps, r.replans, r.message, r.acting_share, r.git_commit "
            "FROM runs r JOIN experiments e ON e.id = r.experimentid ORDER BY e.name, r.planner, r.run")
        rows = [dict(zip(COLUMNS, row)) for row in cursor]
        for row in rows:
            row["acting_share"] = json.loads(row["acting_share"]) if row["acting_share"] else {}
        return rows

    def paths(self, experiment: str) -> Iterator[tuple[str, int, bool, np.ndarray]]:
        """(planner, run, success, end-effector path) of every run of ``experiment``."""
        cursor = self.db.execute(
            "SELECT r.planner, r.run, r.solved, r.ee_path FROM runs r JOIN experiments e ON e.id = r.experimentid "
            "WHERE e.name = ? ORDER BY r.planner, r.run", (experiment,))
        for planner, run, solved, blob in cursor:
            yield planner, int(run), bool(solved), decode_path(blob)
