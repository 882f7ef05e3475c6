"""Shipping a run's policy: the bundle copied with its metadata beside it."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING

from rayreach.learning.bundles import CheckpointError, _json_default, read_bundle_meta

if TYPE_CHECKING:
    from rayreach.learning.train import TrainConfig


def train_command(config: dict, out: str | Path) -> str:
    """The ``rayreach train`` command line a run's saved configuration stands for, with the
    flags that stay on through ``--resume`` (the suite, acting layers, rays beyond the recipe's for
    the robot, a fixed obstacle count); flags
    given to one part only (``--freeze-features``, ``--critic-warmup``) are not saved."""
    command = (f"rayreach train --robot {config['robot']} --timesteps {config['timesteps']} --envs {config['envs']} "
               f"--out {out} --checkpoint-every {config['checkpoint_every']}")
    name = config.get("recipe", "baseline")  # a run saved before recipes were named was the baseline
    if name != "default":
        command = command.replace(" --robot", f" --recipe {name} --robot", 1)
    if config.get("suite", "random") != "random":
        command += f" --suite {config['suite']}"
    if config.get("acting_layers"):
        command += " --acting-layers"
    observation = config.get("observation")
    from rayreach.learning.train import RECIPES, recipe
    from rayreach.sim.sensors import EXTRA_RAYS

    suite = config.get("suite", "random")
    usual = recipe(name, robot=config["robot"], suite=suite) if name in RECIPES else None
    if isinstance(observation, dict) and usual is not None:
        for field, (flag, _, _) in EXTRA_RAYS.items():
            if observation.get(field, False) != getattr(usual.observation, field):
                command += f" --{'' if observation.get(field) else 'no-'}{flag}"
        if observation.get("goal_sight", False) != usual.observation.goal_sight:
            command += f" --{'' if observation.get('goal_sight') else 'no-'}goal-sight"
        if observation.get("privileged"):
            command += " --privileged"
    period = config.get("decision_period", 1)  # a run saved before the choice decided every step
    if usual is not None and period != usual.decision_period:
        command += f" --decision-period {period}"
    if usual is not None and config.get("gamma", usual.gamma) != usual.gamma:
        command += f" --gamma {config['gamma']:g}"
    if config.get("extra_kinds"):
        command += f" --extra-kinds {','.join(config['extra_kinds'])}"
    if config.get("cover_speed"):
        command += f" --cover-speed {','.join(f'{v:g}' for v in config['cover_speed'])}"
    if config.get("collision_margin"):
        command += f" --collision-margin {config['collision_margin']:g}"
    for field in ("collision_weight", "out_of_bounds_weight", "action_std_init"):
        saved = config.get(field, getattr(RECIPES["baseline"], field))  # config_from_meta's rule
        if usual is not None and saved != getattr(usual, field):
            command += f" --{field.replace('_', '-')} {saved:g}"
    every = config.get("validate_every")  # None: saved before runs validated (validating changes no weights)
    if every is not None and usual is not None and every != usual.validate_every:
        command += f" --validate-every {every}"
    if every and config["validate_worlds"] != RECIPES["default"].validate_worlds:
        command += f" --validate-worlds {config['validate_worlds']}"
    if usual is not None and config.get("starts", 1) != usual.starts:
        command += f" --starts {config.get('starts', 1)}"
    length = config.get("start_decisions")
    if usual is not None and config.get("starts", 1) > 1 and length not in (None, usual.start_decisions):
        command += f" --start-decisions {length}"
    return command + _obstacle_flag(config.get("obstacles", {}), usual) + " [--resume]"


def _obstacle_flag(obstacles: dict, usual: TrainConfig | None) -> str:
    """The flag that sets a run's obstacles where they are not its recipe's: a fixed count, an
    even mix, or the curriculum (the broad recipe's default is the mix; runs before it climbed)."""
    if not obstacles:
        return ""
    saved = _obstacle_rule(obstacles["start"], obstacles["minimum"], obstacles["maximum"], obstacles.get("mix", False))
    if usual is not None:
        theirs = usual.obstacles
        if saved == _obstacle_rule(theirs.start, theirs.minimum, theirs.maximum, theirs.mix):
            return ""
    name, count = saved
    if name != "curriculum":
        return f" --{name} {count}"
    return " --obstacle-curriculum" if usual is not None else ""


def _obstacle_rule(start: int, minimum: int, maximum: int, mix: bool) -> tuple[str, int | bool]:
    """How a run sets its worlds' obstacle counts: the flag of a fixed count or an even mix
    with that count, else the curriculum (with whether it mixes)."""
    if minimum == maximum == start:
        return ("obstacle-mix" if mix else "obstacles"), start
    return "curriculum", mix


def run_bundle(source: str | Path) -> Path:
    """A bundle file as it is, or a run directory's choice: the best.zip its validations kept
    (``rayreach.learning.selection``), else the newer of model.zip and checkpoint.zip."""
    from rayreach.learning.selection import BEST

    source = Path(source)
    if source.is_dir() and (source / BEST).exists():
        return source / BEST
    if source.is_dir():
        found = [c for c in (source / "model.zip", source / "checkpoint.zip") if c.exists()]
        if not found:
            raise CheckpointError(f"{source} holds neither model.zip nor checkpoint.zip")
        return max(found, key=lambda c: read_bundle_meta(c)[0]["timesteps"])
    return source


def export_bundle(source: str | Path, target: str | Path) -> tuple[Path, Path]:
    """Copy a run's model (or its latest checkpoint) to ``target`` and write the metadata
    beside it as ``target`` with a .json suffix: what a shipped policy carries."""
    import shutil

    source, target = run_bundle(source), Path(target)
    meta, _ = read_bundle_meta(source)
    target.parent.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(source, target)
    info = {k: meta.get(k) for k in ("robot", "kind", "timesteps", "wall_time_s", "machine", "git_commit", "command")}
    if not info["command"]:  # checkpoints do not record the command line; this reproduces the run
        info["command"] = train_command(meta["config"], source.parent)
    info["source"] = str(source)
    info["curriculum"] = {"goal_size": meta["state"]["goal"]["size"], "obstacles": meta["state"]["obstacles"]["count"],
                          "episodes": meta["state"]["episodes"]}
    info["config"] = meta["config"]
    best = meta["state"].get("best")
    if best and best["timesteps"] == meta["timesteps"]:  # best.zip: the figures it was chosen on
        info["validation"] = best
    # demonstrations cloned into the checkpoint (rayreach.learning.demonstrations) leave their reports beside it
    info["demonstrations"] = [json.loads(r.read_text()) for r in sorted(source.parent.glob("clone-*.json"))]
    json_path = target.with_suffix(".json")
    json_path.write_text(json.dumps(info, indent=2, default=_json_default) + "\n")
    return target, json_path
