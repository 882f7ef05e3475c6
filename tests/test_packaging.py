"""rayreach as an installed package: shipped policies by robot name, ``rayreach robots``, the wheel."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import tomllib
import zipfile
from importlib import metadata, resources
from pathlib import Path

import pytest

from rayreach import ENV_IDS
from rayreach.cli import main
from rayreach.planners.drl import MODELS_DIR, resolve_model, shipped_model, shipped_robots

ROOT = Path(__file__).resolve().parents[1]
SHIPPED = ("ur5.zip", "ur5.json", "kr16.zip", "kr16.json", "ur10.zip", "ur10.json")


def test_shipped_policies_are_package_data_of_rayreach_models():
    assert MODELS_DIR == Path(str(resources.files("rayreach.models")))
    assert all((MODELS_DIR / name).is_file() for name in SHIPPED)
    assert shipped_robots() == ("ur5", "kr16", "ur10")


def test_resolver_takes_robot_names_and_paths(tmp_path, monkeypatch):
    assert resolve_model("ur5") == shipped_model("ur5") == MODELS_DIR / "ur5.zip"
    assert resolve_model("KR16") == MODELS_DIR / "kr16.zip"
    own = tmp_path / "mine.zip"
    own.write_bytes((MODELS_DIR / "ur5.zip").read_bytes())
    assert resolve_model(own) == own and resolve_model(str(own)) == own
    monkeypatch.chdir(tmp_path)
    (tmp_path / "kr16").write_bytes(b"x")  # an existing file wins over a robot name
    assert resolve_model("kr16") == Path("kr16")
    missing = tmp_path / "runs" / "missing.zip"  # a path that is not there: the loader names it
    assert resolve_model(missing) == missing and resolve_model("missing.zip") == Path("missing.zip")


def test_resolver_names_the_robots_and_paths_for_a_bad_name():
    with pytest.raises(FileNotFoundError) as bad:
        resolve_model("ur7")
    message = str(bad.value)
    assert "'ur7'" in message and "ur5, kr16, ur10" in message and "path" in message
    with pytest.raises(FileNotFoundError, match="no shipped policy for 'abb'; shipped: ur5, kr16, ur10"):
        shipped_model("abb")


def test_cli_model_options_take_robot_names(capsys):
    assert main(["rollout", "--model", "ur7", "exp1", "--json"]) == 2
    assert "ur5, kr16, ur10" in capsys.readouterr().err
    assert main(["bench-acting", "--model", "ur7"]) == 2
    assert "'ur7'" in capsys.readouterr().err
    assert main(["rollout", "--model", "ur5", "exp1", "--episodes", "1", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert summary["scenario"] == "exp1" and summary["success_rate"] == 1.0


def test_robots_lists_each_robot_with_its_source(capsys):
    assert main(["robots", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert [r["name"] for r in rows] == ["ur5", "kr16", "ur10"]
    by_name = {r["name"]: r for r in rows}
    assert by_name["ur5"]["package"] == by_name["ur10"]["package"] == "example-robot-data"
    assert by_name["kr16"]["package"] == "rtb-data"
    assert [r["kinematics"] for r in rows] == ["DH table", "DH table", "URDF joints"]
    assert all(r["dof"] == 6 for r in rows)
    assert all(Path(r["policy"]).is_file() for r in rows if r["shipped_policy"])
    assert [r["name"] for r in rows if r["shipped_policy"]] == list(shipped_robots())
    assert [r["env_id"] for r in rows] == ["rayreach/Reach-UR5-v0", "rayreach/Reach-KR16-v0", "rayreach/Reach-UR10-v0"]
    assert all(r["env_id"] in ENV_IDS for r in rows)
    assert main(["robots"]) == 0
    table = capsys.readouterr().out.splitlines()
    assert table[0].split()[:3] == ["robot", "URDF", "package"]
    assert table[1].split()[:2] == ["ur5", "example-robot-data"]


def test_pyproject_lists_every_package():
    """packages.find cannot map rayreach.models to models/, so the list is by hand; a package
    missing from it would be missing from the wheel only."""
    setuptools = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    inits = (ROOT / "src" / "rayreach").rglob("__init__.py")
    on_disk = {".".join(p.parent.relative_to(ROOT / "src").parts) for p in inits}
    assert set(setuptools["packages"]) == on_disk | {"rayreach.models"}, "add the package to pyproject.toml"
    assert setuptools["package-dir"]["rayreach.models"] == "models"


def test_wheel_carries_the_shipped_policies_and_no_training_runs(tmp_path):
    """What a clean clone builds: pyproject, README, src/ and all of models/ with its train-* runs."""
    tree = tmp_path / "tree"
    tree.mkdir()
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(ROOT / name, tree / name)
    shutil.copytree(ROOT / "src", tree / "src", ignore=shutil.ignore_patterns("__pycache__", "*.egg-info"))
    shutil.copytree(ROOT / "models", tree / "models",
                    ignore=shutil.ignore_patterns("__pycache__", "tensorboard"))
    assert any(p.name.startswith("train-") for p in (tree / "models").iterdir())
    # the venv's setuptools builds it where new enough (no download); otherwise pip's isolated build
    new_setuptools = int(metadata.version("setuptools").split(".")[0]) >= 77
    isolation = ["--no-build-isolation"] if new_setuptools else []
    command = [sys.executable, "-m", "pip", "wheel", "--no-deps", *isolation, ".", "-w", "dist", "-q"]
    build = subprocess.run(command, cwd=tree, capture_output=True, text=True, timeout=600)
    assert build.returncode == 0, build.stderr[-2000:]
    (wheel,) = (tree / "dist").glob("rayreach-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    assert {f"rayreach/models/{name}" for name in SHIPPED} <= set(names)
    assert not [n for n in names if "train-" in n]
    models = sorted(n for n in names if n.startswith("rayreach/models/"))
    data = (*SHIPPED, "arm_capsules.json")  # and the arm's capsules (rayreach.acting.arm_guard)
    assert models == sorted(["rayreach/models/__init__.py", *(f"rayreach/models/{name}" for name in data)])
    modules = {str(p.relative_to(ROOT / "src")) for p in (ROOT / "src" / "rayreach").rglob("*.py")}
    assert modules <= set(names)  # every module of the checkout is in the wheel
    assert "rayreach/scenarios/data/exp1.json" in names
