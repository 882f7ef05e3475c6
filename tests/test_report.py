"""Report: the representative run, obstacle solids, the policy's share of steps in the table."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest

from rayreach.evaluate.report import (markdown_table, obstacle_faces, representative, summarise, trajectory_figure,
                                      write_csv)
from rayreach.evaluate.runner import crash_record
from rayreach.evaluate.store import COLUMNS, ResultsStore
from rayreach.scenarios import ObstacleSpec


def _line(length: float) -> np.ndarray:
    return np.array([[0.0, 0.0, 0.0], [length, 0.0, 0.0]])


def test_the_representative_is_the_median_length_success_else_the_median_length_run():
    runs = [(False, _line(0.1)), (True, _line(3.0)), (True, _line(1.0)), (True, _line(2.0)), (False, _line(9.0))]
    assert representative(runs) == 3  # successes 1.0, 2.0, 3.0: the 2.0 one
    assert representative(runs[:3]) == 2  # 1.0 and 3.0: the shorter middle one
    assert representative([(False, _line(5.0)), (False, _line(1.0)), (False, _line(2.0))]) == 2
    with pytest.raises(ValueError, match="no runs"):
        representative([])


def test_obstacle_faces_lie_on_the_obstacles_surface_where_it_is_at_t0():
    box = ObstacleSpec("box", (0.1, 0.2, 0.3), rpy=(0.3, 0.0, 0.5), half_extents=(0.1, 0.2, 0.05),
                       velocity=(0.0, 0.2, 0.0))
    faces = obstacle_faces(box)
    assert len(faces) == 6 and all(f.shape == (4, 3) for f in faces)
    np.testing.assert_allclose(np.mean(np.vstack(faces), axis=0), box.position, atol=1e-12)
    sphere = ObstacleSpec("sphere", (0.0, 0.5, 0.4), radius=0.07)
    points = np.vstack(obstacle_faces(sphere))
    np.testing.assert_allclose(np.linalg.norm(points - sphere.position, axis=1), 0.07)
    cylinder = ObstacleSpec("cylinder", (0.2, 0.0, 0.5), rpy=(np.pi / 2, 0.0, 0.0), radius=0.05, height=0.4)
    points = np.vstack(obstacle_faces(cylinder, resolution=8)) - cylinder.position
    np.testing.assert_allclose(np.hypot(points[:, 0], points[:, 2]), 0.05, atol=1e-12)  # axis along y after roll
    np.testing.assert_allclose(np.abs(points[:, 1]), 0.2, atol=1e-12)
    assert len(obstacle_faces(cylinder, resolution=8)) == 8 + 2
    assert obstacle_faces(ObstacleSpec("mesh", (0.0, 0.0, 0.0), file="part.obj")) == []


def test_box_faces_follow_pybullets_pose_of_a_rotated_box():
    """The drawn faces of a box with roll, pitch and yaw have their corners where PyBullet
    places them for the same pose, and each face is a rectangle of two of the box's sides."""
    import pybullet as pb

    centre, half, rpy = (0.4, -0.1, 0.3), (0.05, 0.1, 0.002), (0.3, -0.2, 1.1)
    quat = pb.getQuaternionFromEuler(rpy)
    expected = np.array([pb.multiplyTransforms(centre, quat, (sx * half[0], sy * half[1], sz * half[2]),
                                               (0, 0, 0, 1))[0]
                         for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    faces = obstacle_faces(ObstacleSpec("box", centre, rpy=rpy, half_extents=half))
    assert len(faces) == 6
    ends = np.unique(np.round(np.vstack(faces), 9), axis=0)
    assert len(ends) == 8
    nearest = np.linalg.norm(ends[:, None] - expected[None], axis=2)  # PyBullet computes in float32
    assert np.all(nearest.min(axis=1) < 1e-6) and len(set(nearest.argmin(axis=1))) == 8
    sides = sorted(2 * h for h in half)
    for face in faces:
        lengths = np.linalg.norm(np.diff(np.vstack((face, face[:1])), axis=0), axis=1)
        np.testing.assert_allclose(lengths[:2], lengths[2:])  # opposite sides equal
        pairs = [[sides[i], sides[j]] for i in range(3) for j in range(i + 1, 3)]
        assert sorted(np.round(lengths[:2], 9).tolist()) in pairs


def _row(planner: str, share: dict[str, float], solved: int = 1) -> dict:
    return {"experiment": "random-ur5@test", "planner": planner, "solved": solved, "collision": 0,
            "status": "success" if solved else "timeout", "execution_time": 1.0, "solution_length": 0.5, "time": 0.1,
            "acting_share": share}


def test_the_table_shows_the_policys_mean_share_beside_success_for_reactive_planners_only(tmp_path):
    rows = [_row("drl", {"policy": 0.6, "final_approach": 0.4}), _row("drl", {"policy": 0.8, "detour": 0.2}, 0),
            _row("drl", {}), _row("rrt", {}), _row("rrt", {})]
    stats = summarise(rows)
    assert stats[("random-ur5@test", "drl")]["policy_share"] == pytest.approx(0.7)  # runs without shares left out
    assert stats[("random-ur5@test", "rrt")]["policy_share"] is None
    table = markdown_table(rows)
    assert "| random-ur5@test | 2/3 (0 coll.; policy 70%) | 2/2 (0 coll.) |" in table
    with open(write_csv([{**dict.fromkeys(COLUMNS), **r} for r in rows], tmp_path / "runs.csv")) as f:
        shares = [r["acting_share"] for r in csv.DictReader(f)]
    assert json.loads(shares[0]) == {"final_approach": 0.4, "policy": 0.6} and shares[2:] == ["", "", ""]


def test_the_trajectory_figure_draws_every_shape_and_a_planner_without_success(tmp_path):
    """Spheres, cylinders, a moving box, two goals, and a planner whose runs all failed."""
    scene = {"name": "shapes", "robot": "ur5", "start": {"joints": [0, -1.6, 1.6, 0, 1.6, 0]},
             "goals": [[-0.2, 0.45, 0.3], [0.2, 0.45, 0.3]],
             "workspace": {"low": [-0.4, 0.3, 0.2], "high": [0.4, 0.7, 0.5]},
             "obstacles": [{"shape": "sphere", "position": [0.0, 0.45, 0.3], "radius": 0.05},
                           {"shape": "cylinder", "position": [0.1, 0.5, 0.3], "radius": 0.03, "height": 0.2},
                           {"shape": "box", "position": [-0.1, 0.4, 0.3], "half_extents": [0.05, 0.05, 0.002],
                            "velocity": [0.0, 0.2, 0.0]}]}
    path = tmp_path / "shapes.json"
    path.write_text(json.dumps(scene))
    store = ResultsStore(tmp_path / "results.db")
    for run, (planner, success) in enumerate([("drl", True), ("drl", True), ("rrt", False), ("rrt", False)]):
        record = crash_record(planner, "shapes", run, "")
        record.success = success
        record.ee_path = np.linspace([0.3, 0.4, 0.3], [-0.2, 0.45, 0.3 + 0.05 * run], 20)
        store.add(str(path), "ur5", 0.01, run, record, {}, None)
    png = trajectory_figure(store, [str(path)], ["drl", "rrt"], tmp_path / "shapes.png")
    store.close()
    assert png.stat().st_size > 10_000
