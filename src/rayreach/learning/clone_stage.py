"""The demonstration stage of a run: PPO to ``TrainConfig.clone_at`` decisions, the scripted
experts of ``clone_kinds`` cloned into the actor one after the other, then PPO on from the
clone to the end.

In broad worlds PPO alone learned the tables and hardly the open boxes and shelves; with
their experts cloned at 6.4 M decisions the UR5 alone reached the goal in 75 of 104 boxes and
54 of 114 shelves by 12.8 M, against 12 and 9 without (docs/training.md, "Broad worlds").
Done by hand that took three commands; here ``rayreach train`` runs them.

An interrupted run resumes with ``--resume``: before the clone as any run, then each kind
not yet cloned is cloned, and the rest trains. A kind is cloned once its checkpoint holds the
report (saved with the cloned actor in one write) or its ``clone-KIND.json`` is in the run
directory (runs saved before the checkpoint held them). The first ``CLONE_CRITIC_WARMUP``
decisions after the clone fit the critic alone, as the measured runs did: its values were
learned for the actor before the clone.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path
from typing import Any

from rayreach.learning.bundles import CheckpointError, read_bundle_meta
from rayreach.learning.demonstrations import CLONES, CloneConfig, clone_into_checkpoint, report_name, write_report
from rayreach.learning.imitation import demos_name, load_demos
from rayreach.learning.starts import train_with_starts
from rayreach.learning.train import CHECKPOINT, TrainConfig, config_from_meta, train

STAGE_CLONE = CloneConfig(episodes=100, anchor_episodes=100, eval_episodes=40, anchor_tolerance=0.01)
"""The sizes of the measured broad clones (docs/training.md, "Broad worlds"): 713 s for the
open box and 465 s for the shelf on one core."""
CLONE_CRITIC_WARMUP = 100_000
"""Decisions after the clone in which only the critic learns."""


def clone_plan(config: TrainConfig, out: Path, resume: bool, overrides: dict[str, Any]) -> TrainConfig:
    """The clone settings a run goes by: a resumed run's own (saved with its checkpoint),
    unless ``overrides`` names them; a new run's from ``config``."""
    if not (resume and (out / CHECKPOINT).exists()):
        return config
    saved = config_from_meta(read_bundle_meta(out / CHECKPOINT)[0])
    names = ("clone_at", "clone_kinds")
    return replace(config, **{n: overrides.get(n, getattr(saved, n)) for n in names})


def checkpoint_steps(out: Path) -> int | None:
    """Decisions of the run's checkpoint; None where it has none."""
    path = out / CHECKPOINT
    return int(read_bundle_meta(path)[0]["timesteps"]) if path.exists() else None


def cloned_kinds(out: Path, kinds: tuple[str, ...]) -> set[str]:
    """Those of ``kinds`` cloned into the run's checkpoint. A report the checkpoint holds but the
    directory lacks (a stop between the two writes) is written out again."""
    held = read_bundle_meta(out / CHECKPOINT)[0]["state"].get(CLONES, {}) if (out / CHECKPOINT).exists() else {}
    for kind in set(kinds) & set(held):
        if not (out / report_name(kind)).exists():
            write_report(out, held[kind])
    return {kind for kind in kinds if (out / report_name(kind)).exists()}


def warmup_left(steps: int, cloned_at: int) -> int:
    """Decisions of the critic's warm-up still to come at ``steps`` (a run stopped inside it
    finishes it when resumed)."""
    return max(0, cloned_at + CLONE_CRITIC_WARMUP - steps)


def train_with_clone(config: TrainConfig, out: str | Path, resume: bool = False, command: str = "",
                     resume_overrides: dict[str, Any] | None = None, clone: CloneConfig = STAGE_CLONE,
                     progress: bool = True, critic_warmup: int = 0, **train_kwargs: Any) -> Path:
    """``train_with_starts`` for a config that clones experts (without ``clone_kinds``, or with
    no more decisions than ``clone_at``, that alone); the same arguments and the same model
    bundle at the end. ``clone``: the sizes of each kind's cloning."""
    out = Path(out)
    overrides = resume_overrides or {}
    config = clone_plan(config, out, resume, overrides)
    if not resume:
        left = sorted(p.name for pattern in (report_name("*"), demos_name("*")) for p in out.glob(pattern))
        if left:
            raise CheckpointError(f"{', '.join(left)} in {out} are left from an earlier run: pass --resume to "
                                  "continue it, or choose another --out")
    if config.imitation_steps and not config.clone_kinds:
        load_demos(out)  # before any training: an imitation term without a clone needs them now
    if not config.clone_kinds or config.timesteps <= config.clone_at:
        return train_with_starts(config, out, resume=resume, command=command, resume_overrides=resume_overrides,
                                 critic_warmup=critic_warmup, **train_kwargs)
    done = cloned_kinds(out, config.clone_kinds) if resume else set()
    pending = [k for k in config.clone_kinds if k not in done]
    if pending and (critic_warmup or any(train_kwargs.values())):
        given = ["critic_warmup"] * bool(critic_warmup) + [k for k, v in train_kwargs.items() if v]
        raise ValueError(f"{', '.join(given)} apply to one part of a run: give them to a --resume after its "
                         f"clone of {', '.join(pending)}")
    if pending:
        steps = checkpoint_steps(out) if resume else None
        if steps is None or steps < config.clone_at:
            train_with_starts(replace(config, timesteps=config.clone_at), out, resume=resume, command=command,
                              resume_overrides=resume_overrides)
            resume_overrides = None  # the first part saved them with its checkpoint
        for kind in pending:
            print(f"clone: the {kind} expert into {out / CHECKPOINT}", flush=True)
            report = clone_into_checkpoint(out, kind, clone, progress)
            print(f"clone: {kind} done in {report['wall_time_s']:.0f} s; its worlds with the final approach "
                  f"{report['expert_worlds']['before']['success']:.0%} before, "
                  f"{report['expert_worlds']['after']['success']:.0%} after", flush=True)
    cloned_at = max(json.loads((out / report_name(k)).read_text())["timesteps"] for k in config.clone_kinds)
    critic_warmup = max(critic_warmup, warmup_left(checkpoint_steps(out) or 0, cloned_at))
    return train(config, out, resume=True, command=command, resume_overrides=resume_overrides if resume else None,
                 critic_warmup=critic_warmup, **train_kwargs)
