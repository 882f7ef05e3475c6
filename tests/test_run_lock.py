"""One trainer per run directory (``rayreach.learning.run_lock``): a second one is refused
with the holder's process id, and the lock goes with its holder however that ends."""

from __future__ import annotations

import signal
import subprocess
import sys
import time

import pytest

from rayreach.learning.run_lock import LOCK, RunLockedError, held

PROBE = ("import sys; from rayreach.learning.run_lock import RunLockedError, held\ntry:\n    with held(sys.argv[1]):\n"
         "        print('free')\nexcept RunLockedError:\n    print('locked')")
HOLD = "import sys, time; from rayreach.learning.run_lock import held\nwith held(sys.argv[1]):\n    print('held', flush=True)\n    time.sleep(60)"


def _holder(out):
    process = subprocess.Popen([sys.executable, "-c", HOLD, str(out)], stdout=subprocess.PIPE, text=True)
    assert process.stdout.readline().strip() == "held"
    return process


def test_a_second_process_is_refused_until_the_first_is_killed(tmp_path):
    out = tmp_path / "run"
    process = _holder(out)
    try:
        with pytest.raises(RunLockedError, match=rf"being trained by another process \(pid {process.pid}\)"):
            with held(out):
                pass
    finally:
        process.send_signal(signal.SIGKILL)
        process.wait()
    with held(out):  # a killed holder leaves no stale lock
        assert (out / LOCK).read_text().strip().isdigit()


def _probe(out) -> str:
    return subprocess.run([sys.executable, "-c", PROBE, str(out)], capture_output=True, text=True, check=True).stdout.strip()


def test_the_holder_takes_its_directory_again_and_keeps_it_until_the_outer_block_ends(tmp_path):
    out = tmp_path / "run"
    with held(out):
        with held(tmp_path / "." / "run"):  # the parent of several starts going on with the chosen run
            assert _probe(out) == "locked"
        assert _probe(out) == "locked"
    assert _probe(out) == "free"


def test_train_is_refused_while_another_process_trains_into_the_directory(tmp_path):
    from rayreach.learning.train import TrainConfig, train

    out = tmp_path / "run"
    process = _holder(out)
    try:
        started = time.monotonic()
        with pytest.raises(RunLockedError, match="stop it before resuming, or choose another --out"):
            train(TrainConfig(robot="ur5", timesteps=64), out)
        assert time.monotonic() - started < 5  # refused before building anything
        assert not any(p.name != LOCK for p in out.iterdir())
    finally:
        process.send_signal(signal.SIGKILL)
        process.wait()


def test_a_resume_without_a_checkpoint_leaves_no_directory_behind(tmp_path):
    from rayreach.learning.bundles import CheckpointError
    from rayreach.learning.train import TrainConfig, train

    with pytest.raises(CheckpointError, match="no checkpoint"):
        train(TrainConfig(robot="ur5", timesteps=64), tmp_path / "typo", resume=True)
    assert not (tmp_path / "typo").exists()
