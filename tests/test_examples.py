"""Every script in examples/ runs as a user would run it and writes its file.

An example takes ``--out FILE`` for what it writes; each runs in its own process, from a
folder outside the checkout, so it sees rayreach only as installed."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

EXAMPLES = sorted((Path(__file__).resolve().parents[1] / "examples").glob("*.py"))


def test_there_are_examples():
    assert "plan_scene_in_code.py" in [p.name for p in EXAMPLES]


@pytest.mark.parametrize("example", EXAMPLES, ids=[p.stem for p in EXAMPLES])
def test_example_runs_and_writes_its_file(example, tmp_path):
    out = tmp_path / f"{example.stem}.png"
    done = subprocess.run([sys.executable, str(example), "--out", str(out)], cwd=tmp_path,
                          capture_output=True, text=True, timeout=240)
    assert done.returncode == 0, done.stderr[-3000:]
    assert out.is_file() and out.stat().st_size > 1000
    assert f"wrote {out}" in done.stdout
