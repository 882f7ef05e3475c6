"""The ``rayreach`` command. Arguments are parsed before PyBullet or torch are imported."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Sequence

from rayreach.robots import ROBOTS  # specs only: numpy, no simulator
from rayreach.scenarios import WORLD_SUITES  # names only: the scene schema, no simulator

EVAL_PLANNERS = "drl,rrt,ncrrt,ompl-rrt,ompl-rrtconnect"
TRAIN_RECIPES = ("default", "baseline", "paper")
"""``rayreach.learning.train.RECIPES``' names (that module imports torch's stack)."""
COMPARE_VARIANTS = ("baseline", "default", "paper", "paper-observation", "no-scans", "long-scans", "sightings",
                    "no-workspace", "entropy", "around-obstacles", "proximity", "gamma-0.995", "gamma-0.998",
                    "tip-back", "no-tip-back", "collision-20", "collision-40", "more-covers", "slow-covers",
                    "separate-features", "wide", "decide-1", "decide-2", "decide-8", "slanted", "slanted-no-tip-back",
                    "goal-sight")
"""``rayreach.evaluate.compare_recipes.VARIANTS``' names."""
ROBOT_HELP = " or ".join(ROBOTS)

LAYER_HELP = {"final_approach": "straight final approach near the goal", "ray_shield": "ray shield and its hit memory",
              "slide": "shield's slide towards the goal", "workspace_guard": "workspace guard",
              "arm_guard": "arm's rule (blind links and tool kept off what the rays saw)",
              "detour": "detour round what the rays saw for a stalled policy",
              "resample": "fresh draw of the action where the arm was held"}
"""One switch per acting layer (``rayreach.acting.LAYERS``), for ``rollout``."""


def _scenario_arg(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "scenario_pos", nargs="?", metavar="SCENARIO", help="exp1..exp7 or a scene .json file"
    )
    parser.add_argument("--scenario", dest="scenario_opt", help="same as the positional SCENARIO")


MODEL_HELP = f"{ROBOT_HELP} (that robot's shipped policy), or a model or checkpoint .zip"


def _model(name_or_path: str):
    """The policy file an option names (``rayreach.planners.drl.resolve_model``)."""
    from rayreach.planners.drl import resolve_model

    return resolve_model(name_or_path)


def _pick_scenario(args: argparse.Namespace, parser: argparse.ArgumentParser) -> str:
    scenario = args.scenario_opt or args.scenario_pos
    if not scenario:
        parser.error("give a scenario: exp1..exp7 or a path to a scene .json file")
    return scenario


def build_parser() -> argparse.ArgumentParser:
    from rayreach.learning.demonstrations import EXPERTS, CloneConfig  # numpy only
    from rayreach.learning.distill import DistillConfig  # numpy only
    from rayreach.acting.detour import Detour  # numpy only
    from rayreach.acting.final_approach import FinalApproach  # numpy only
    from rayreach.acting.resample import HELD_DRAW_STD  # numpy only
    from rayreach.acting.shield import ACTING_SAFETY, SLIDE  # numpy only
    from rayreach.scenarios.splits import EVALUATION_SPLITS  # no imports

    parser = argparse.ArgumentParser(prog="rayreach", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)

    show = sub.add_parser("show", help="render a scenario with its rays to a PNG (or open the GUI)")
    _scenario_arg(show)
    show.add_argument("--out", default=None, help="PNG file to write (default: SCENARIO.png)")
    show.add_argument("--gui", action="store_true", help="open PyBullet's GUI instead (needs a display)")
    show.add_argument("--seed", type=int, default=0)
    show.add_argument("--planner", default=None, help="run this planner (drl, rrt, ncrrt, ...) and draw its path")
    show.add_argument("--model", default=None, help=f"DRL policy: {MODEL_HELP} (default: the robot's shipped one)")
    show.add_argument("--video", default=None, help="also write the run as a GIF, e.g. exp4.gif")

    bench = sub.add_parser("bench-env", help="environment steps per second for both ray backends")
    bench.add_argument("--robot", default="ur5", help=ROBOT_HELP)
    bench.add_argument("--scenario", default="exp1", help="exp1..exp7, random, or a scene file")
    bench.add_argument("--steps", type=int, default=3000)
    bench.add_argument("--rounds", type=int, default=3, help="interleaved blocks per backend")
    bench.add_argument("--json", action="store_true", help="print one JSON line")
    bench.add_argument("--breakdown", action="store_true", help="also time each part of a step (us per call)")
    bench.add_argument("--batched", type=int, default=None, metavar="N",
                       help="compare the single env with the batched env of N worlds instead of the ray backends")

    bact = sub.add_parser("bench-acting", help="microseconds per step of the acting stack, minus each layer, and alone")
    bact.add_argument("--model", required=True, help=MODEL_HELP)
    bact.add_argument("--episodes", type=int, default=10, help="random worlds, each run by every variant in turn")
    bact.add_argument("--obstacles", type=int, default=None, help="obstacles per world (default: training's)")
    bact.add_argument("--split", choices=EVALUATION_SPLITS, default="validation")
    bact.add_argument("--json", action="store_true", help="print one JSON line")

    bplan = sub.add_parser("bench-planners", help="planning time, path length and collision checks/s of the planners")
    bplan.add_argument("--scenario", default="exp1", help="exp1..exp7 or a scene file")
    bplan.add_argument("--runs", type=int, default=10)
    bplan.add_argument("--planners", default=None,
                       help="comma-separated (default: rrt,ncrrt,birrt and the OMPL peers when installed)")
    bplan.add_argument("--time-limit", type=float, default=30.0, help="seconds per planning query")
    bplan.add_argument("--json", action="store_true", help="print one JSON line")

    bgoal = sub.add_parser("bench-goals", help="worlds left without a collision-free goal configuration, by IK "
                           "seed count, and the goal IK's time (no planning)")
    bgoal.add_argument("--suite", default="broad", help="random or broad (default broad)")
    bgoal.add_argument("--robot", default="ur5", help=ROBOT_HELP)
    bgoal.add_argument("--worlds", type=int, default=100)
    bgoal.add_argument("--first-seed", type=int, default=1_000_000, help="default: the validation split")
    bgoal.add_argument("--more-seeds", default="0,256", help="comma-separated goal_ik_more_seeds counts")
    bgoal.add_argument("--from-home", action="store_true", help="seed the IK from the home configuration, "
                       "not the start (the suites' worlds are drawn free from the start)")
    bgoal.add_argument("--json", action="store_true")

    ev = sub.add_parser("evaluate", help="the paper's experiments: every planner, N runs, results.db, table, plots")
    ev.add_argument("--experiments", default="1-7", help="e.g. 1-7, 1,3, exp4, random-ur5@test")
    ev.add_argument("--planners", default=None,
                    help="comma-separated, of: drl, drl-alone (the policy without the acting layers), drl-no-LAYER "
                         "(one layer off), rrt, birrt, ncrrt, ompl-rrt, ompl-rrtconnect "
                         f"(default {EVAL_PLANNERS}; --suite random: drl,drl-alone)")
    ev.add_argument("--runs", type=int, default=30, help="runs per experiment and planner")
    ev.add_argument("--suite", choices=WORLD_SUITES, default=None,
                    help="worlds drawn instead of --experiments, from --split's seeds (disjoint from training): "
                         "random, the training worlds; broad, tables, shelves, boxes, clutter and walls in the "
                         "arm's reach")
    ev.add_argument("--split", choices=EVALUATION_SPLITS, default=None,
                    help="seed split of --suite random (default test; stored as experiment random-ROBOT@SPLIT): "
                         "tune on validation, quote test")
    ev.add_argument("--robot", default="ur5,kr16", help="robots of --suite random (comma-separated)")
    ev.add_argument("--episodes", type=int, default=None, help="runs per robot of --suite random")
    ev.add_argument("--obstacles", type=int, default=None,
                    help="obstacles per world of --suite random (default 3, the training curriculum's maximum; "
                         "stored as experiment random-ROBOT:N@SPLIT otherwise)")
    ev.add_argument("--out", required=True, help="results directory, e.g. results/paper")
    ev.add_argument("--workers", type=int, default=None, help="worker processes (default: CPU cores)")
    ev.add_argument("--time-limit", type=float, default=30.0, help="planning time limit per query, s")
    ev.add_argument("--run-timeout", type=float, default=180.0, help="a run taking longer is stored as a crash, s")
    ev.add_argument("--smooth", action="store_true", help="shortcut-smooth the sampling planners' paths")
    ev.add_argument("--replan", action="store_true", help="sampling planners replan when the path becomes invalid")
    ev.add_argument("--model-ur5", default=None, help=f"DRL policy for the UR5: {MODEL_HELP} (default: ur5)")
    ev.add_argument("--model-kr16", default=None, help=f"DRL policy for the KR16: {MODEL_HELP} (default: kr16)")
    ev.add_argument("--report-only", action="store_true", help="only rewrite table, CSV and plots from results.db")
    ev.add_argument("--ray", nargs="?", const="local", default=None, metavar="ADDRESS",
                    help="run the runs as Ray actors: alone, on a local Ray of --workers CPUs; with ADDRESS "
                         "(auto, ray://host:10001), on that cluster, --workers actors (default: its CPUs); "
                         "needs pip install rayreach[ray]")

    train = sub.add_parser("train", help="train a PPO policy on random worlds (resumable)")
    train.add_argument("--robot", required=True, help=ROBOT_HELP)
    train.add_argument("--timesteps", type=int, default=None,
                       help="total environment steps (default: the recipe's, 40 M for default, about 2 h on 2 cores)")
    train.add_argument("--recipe", choices=TRAIN_RECIPES, default="default",
                       help="default: the planner's observation (goal direction, workspace walls, motion, "
                            "remembered scans), 256 batched worlds, 4 minibatches x 5 epochs, adaptive lr 1e-3; "
                            "baseline: the shipped runs' 142 values, 32 environments in worker processes, 256 x 10 "
                            "epochs, lr 3e-4; paper: the paper's agent as published (a resumed run keeps its own)")
    train.add_argument("--envs", type=int, default=None,
                       help="worlds stepped in parallel (default: the recipe's, 256 or 32; the minibatch stays the "
                            "recipe's unless a rollout is smaller; also changes a resumed run)")
    train.add_argument("--workers", type=int, default=None,
                       help="cores to use: worker processes of per-environment stepping and the update's threads "
                            "(default: CPU cores)")
    train.add_argument("--out", default=None, help="run directory (default: runs/ROBOT-RECIPE)")
    train.add_argument("--resume", action="store_true", help="continue the checkpoint in --out")
    train.add_argument("--seed", type=int, default=0)
    train.add_argument("--checkpoint-every", type=int, default=None,
                       help="decisions between checkpoints (default: 100,000; also changes a resumed run)")
    train.add_argument("--validate-every", type=int, default=None, metavar="N",
                       help="decisions between validations of the checkpoint alone on validation worlds, the best "
                            "kept as best.zip (default: the recipe's, 2,500,000; 0: never; a resumed run keeps its "
                            "own, 0 for a run saved before runs validated, unless given)")
    train.add_argument("--validate-worlds", type=int, default=None, metavar="N",
                       help="worlds of each validation (default: 500; given to a resumed run, its choice starts afresh)")
    train.add_argument("--starts", type=int, default=None, metavar="N",
                       help="seeds started side by side (--seed, --seed + 1, ...) on a share of the cores each; the "
                            "best alone on the validation worlds after --start-decisions continues (default: the "
                            "recipe's, 2 for the KR16, else 1)")
    train.add_argument("--start-decisions", type=int, default=None, metavar="N",
                       help="decisions of each start before the choice (default: 5,000,000)")
    train.add_argument("--suite", choices=WORLD_SUITES, default=None,
                       help="the drawn worlds to train in: random (the training box, default) or broad "
                            "(tables, shelves, boxes, clutter, walls up to the arm's reach)")
    train.add_argument("--clone-at", type=int, default=None, metavar="N",
                       help="decisions after which the scripted experts of --clone-kinds are cloned into the actor "
                            "and PPO goes on from the clone (default: the recipe's, 5,000,000 in broad worlds, else "
                            "never)")
    train.add_argument("--clone-kinds", default=None, metavar="KIND[,KIND...]",
                       help="world kinds whose expert is cloned at --clone-at (default: the recipe's, goal_box,shelf "
                            "in broad worlds; '' for none)")
    train.add_argument("--imitation-steps", type=int, default=None, metavar="N",
                       help="behaviour-cloning steps on the run's cloned demonstrations (demos-KIND.npz) before each "
                            "rollout, kept beside PPO (default: 0, none; also changes a resumed run)")
    train.add_argument("--collision-weight", type=float, default=None,
                       help="reward of a collision (the paper's -10; also changes a resumed run)")
    train.add_argument("--out-of-bounds-weight", type=float, default=None,
                       help="reward of leaving the workspace (the paper's -10; also changes a resumed run)")
    train.add_argument("--collision-margin", type=float, default=None, metavar="M",
                       help="distance, m, within which an obstacle counts as hit in training (default 0: touching "
                            "it; also changes a resumed run)")
    train.add_argument("--progress-weight", type=float, default=None,
                       help="weight of the progress reward term (0: the paper's reward alone; also changes a resumed run)")
    train.add_argument("--proximity-weight", type=float, default=None,
                       help="weight of the proximity reward term (0: the paper's reward alone; also changes a resumed run)")
    train.add_argument("--progress-around-obstacles", action=argparse.BooleanOptionalAction, default=None,
                       help="measure the progress term along the shortest way round the static obstacles, not the "
                            "straight line (default: the recipe's; also changes a resumed run)")
    train.add_argument("--shield-weight", type=float, default=None,
                       help="weight of the shielded reward term with --acting-layers (also changes a resumed run)")
    train.add_argument("--extra-kinds", default=None, metavar="KIND[,KIND...]",
                       help="obstacle kinds drawn beside the robot's training kinds, a kind listed again drawn more "
                            "often (e.g. goal_cover,goal_cover; '' for none; also changes a resumed run)")
    train.add_argument("--cover-speed", default=None, metavar="LOW,HIGH",
                       help="speed range, m/s, of the training worlds' goal covers (default: the suites' 0.05,0.2; "
                            "also changes a resumed run)")
    train.add_argument("--target-kl", type=float, default=None, help="early-stop updates at this KL (0: never)")
    train.add_argument("--separate-features", action="store_true", help="actor and critic get their own extractor")
    train.add_argument("--obstacles", type=int, default=None,
                       help="fix the obstacle count (no obstacle curriculum; also holds a resumed run's count)")
    train.add_argument("--obstacle-mix", type=int, default=None, metavar="N",
                       help="spread the worlds evenly over 1 to N obstacles, for the whole run (no obstacle "
                            "curriculum; also changes a resumed run)")
    train.add_argument("--obstacle-curriculum", action="store_true",
                       help="raise the obstacle count from 1 as training succeeds, where the suite's recipe "
                            "fixes or mixes it (the broad recipe mixes 1 to 3; also changes a resumed run)")
    train.add_argument("--tip-back", action=argparse.BooleanOptionalAction, default=None,
                       help="read the 24 tip-back rays (default: the recipe's for the robot; a resumed run keeps "
                            "its own observation)")
    train.add_argument("--slanted", action=argparse.BooleanOptionalAction, default=None,
                       help="read the 32 slanted rays along the tool (default: off; a resumed run keeps its own "
                            "observation)")
    train.add_argument("--arm-rays", action=argparse.BooleanOptionalAction, default=None,
                       help="read the 64 rays round the upper arm and the forearm (default: off; a resumed run "
                            "keeps its own observation)")
    train.add_argument("--goal-sight", action=argparse.BooleanOptionalAction, default=None,
                       help="read the 3 rays from the tool aimed at the goal (default: off; a resumed run keeps its "
                            "own observation)")
    train.add_argument("--decision-period", type=int, default=None, metavar="K",
                       help="control steps each action is held for (default: the recipe's, 4; the paper's 1; "
                            "a resumed run keeps its own)")
    train.add_argument("--privileged", action="store_true",
                       help="train a teacher that also sees how near each part of the arm is to the obstacles and "
                            "how they move (batched worlds only; distil it with 'rayreach distill')")
    train.add_argument("--acting-layers", action="store_true",
                       help="train through the acting layers that reshape or refuse the policy's step: shield, "
                            "workspace guard, arm's rule (ActingConfig.training; kept on --resume)")
    train.add_argument("--critic-warmup", type=int, default=0,
                       help="steps at the start of this part in which only the critic learns (after clone)")
    train.add_argument("--learning-rate", type=float, default=None,
                       help="Adam step size (default: the recipe's, 1e-3 adapted to the updates' KL, or baseline's "
                            "3e-4, the paper's; also changes a resumed run and restarts its adaptation)")
    train.add_argument("--action-std-init", type=float, default=None, metavar="STD",
                       help="the action noise's standard deviation at the start of a run from scratch "
                            "(default: 1.0; a resumed run keeps its learned noise)")
    train.add_argument("--gamma", type=float, default=None,
                       help="discount per decision, in (0, 1) (default: the recipe's 0.99; also changes a "
                            "resumed run)")
    train.add_argument("--freeze-features", action="store_true",
                       help="hold the shared feature extractor fixed for this part (fine-tuning after clone)")
    train.add_argument("--goal-size", type=float, default=None, help="fix the goal size, m (no goal curriculum)")
    train.add_argument("--true-goal-share", type=float, default=None,
                       help="share of episodes at the true goal size while the goal is enlarged (default: the "
                            "recipe's, 0.5, the paper's 0; also changes a resumed run)")

    sweep = sub.add_parser("sweep", help="train one run per seed (or per value of a setting), each in its own "
                                         "directory, resumable; on Ray with --ray")
    sweep.add_argument("--robot", required=True, help=ROBOT_HELP)
    sweep.add_argument("--seeds", default="0", help="e.g. 0,1,2 or 0-4: one trial per seed")
    sweep.add_argument("--set", dest="setting", default=None, metavar="FIELD=V1,V2",
                       help="also one trial per value of this TrainConfig field (e.g. learning_rate=3e-4,1e-3)")
    sweep.add_argument("--recipe", choices=TRAIN_RECIPES, default="default")
    sweep.add_argument("--timesteps", type=int, default=None, help="steps per trial (default: the recipe's)")
    sweep.add_argument("--checkpoint-every", type=int, default=100_000, help="steps between checkpoints")
    sweep.add_argument("--out", required=True, help="sweep directory: trial NAME trains into OUT/NAME")
    sweep.add_argument("--ray", nargs="?", const="local", default=None, metavar="ADDRESS",
                       help="each trial a Ray task: alone, on a local Ray; with ADDRESS (auto, ray://host:10001), "
                            "on that cluster (OUT must be seen by every node); needs pip install rayreach[ray]")
    sweep.add_argument("--cpus", type=int, default=2, help="CPUs per trial with --ray (its workers)")

    btrain = sub.add_parser("bench-train", help="training samples per second: the baseline recipe, then the default")
    btrain.add_argument("--robot", default="ur5", help=ROBOT_HELP)
    btrain.add_argument("--seconds", type=float, default=120.0, help="timed seconds per recipe, after a warm-up")
    btrain.add_argument("--json", action="store_true", help="print one JSON line")

    cmp_ = sub.add_parser("compare-recipes", help="the training recipes on one fixed task at equal wall time, "
                                                  "with curves and a validation check")
    cmp_.add_argument("--robot", default="ur5", help=ROBOT_HELP)
    cmp_.add_argument("--minutes", type=float, default=15.0, help="wall time per recipe")
    cmp_.add_argument("--episodes", type=int, default=200, help="validation worlds each final policy runs")
    cmp_.add_argument("--out", required=True, help="directory of the runs, curves.png and summary.json (resumable)")
    cmp_.add_argument("--variants", default="baseline,default",
                      help=f"comma-separated, of: {', '.join(COMPARE_VARIANTS)} (a recipe, or the default recipe "
                           "with one change, e.g. decide-8: a decision every 8 control steps; docs/training.md "
                           "lists what each changes)")
    cmp_.add_argument("--goal", type=float, default=0.1, help="the task's goal radius, m")
    cmp_.add_argument("--obstacles", type=int, default=1, help="the task's obstacles per world")
    cmp_.add_argument("--jobs", type=int, default=1,
                      help="variants trained at once, each on its share of the cores (default: one after another)")

    roll = sub.add_parser("rollout", help="run a saved policy and report success, collisions, path length")
    roll.add_argument("--model", required=True, help=MODEL_HELP)
    _scenario_arg(roll)
    roll.add_argument("--episodes", type=int, default=10)
    roll.add_argument("--stochastic", action="store_true", help="sample actions instead of the mean")
    roll.add_argument("--tolerance", type=float, default=0.01, help="goal tolerance, m (paper: 0.01)")
    roll.add_argument("--obstacles", type=int, default=None, help="obstacles per random world")
    for layer, what in LAYER_HELP.items():
        roll.add_argument(f"--no-{layer.replace('_', '-')}", dest=f"no_{layer}", action="store_true",
                          help=f"switch off the {what} (rayreach.acting)")
    roll.add_argument("--policy-alone", action="store_true", help="switch off every acting layer: the policy alone")
    roll.add_argument("--batched", action="store_true",
                      help="with --policy-alone on random or broad worlds, deterministic: step all episodes' worlds at "
                           "once (one BatchedReachEnv, the same worlds; many times faster)")
    roll.add_argument("--final-approach-radius", type=float, default=None,
                      help="distance to the goal within which the final approach may act, m (default: the robot's, "
                           "UR5 0.1, KR16 0.2)")
    roll.add_argument("--no-turn", action="store_true",
                      help="the final approach never turns the tool towards its path (FinalApproach.turn)")
    roll.add_argument("--guard-arm-rays", action="store_true",
                      help="the arm's rule also reads rays round the upper arm and the forearm and keeps those "
                           "links clear (SafetyLayer.arm_rays)")
    roll.add_argument("--no-give-way", action="store_true",
                      help="the final approach keeps the goal after a veto held one of its steps, instead of "
                           "leaving it to the policy (FinalApproach.give_way)")
    roll.add_argument("--stall-steps", type=int, default=FinalApproach.stall_steps,
                      help="step towards the goal once this many steps brought it less than 1 cm nearer "
                           "(default 0: off)")
    roll.add_argument("--detour-steps", type=int, default=Detour.stall_steps,
                      help="take the detour once this many steps brought the tool less than 1 cm nearer")
    roll.add_argument("--workspace-guard", type=float, default=ACTING_SAFETY.workspace_guard,
                      help="hold the tool this far inside the workspace, m")
    roll.add_argument("--ray-shield", type=float, default=ACTING_SAFETY.ray_shield,
                      help="no motion towards what a ray sees nearer than this, m")
    roll.add_argument("--slide", type=float, default=ACTING_SAFETY.slide,
                      help="step towards the goal when the shield leaves less than this share of the policy's step "
                           f"(default 0: off; {SLIDE:g} is the slide as it was measured)")
    roll.add_argument("--memory-steps", type=int, default=ACTING_SAFETY.memory_steps,
                      help="the shield also holds off what the rays saw near in this many last steps")
    roll.add_argument("--arm-clearance", type=float, default=ACTING_SAFETY.arm_clearance,
                      help="refuse steps that bring an arm link nearer than this to what the rays saw in the last "
                           f"{ACTING_SAFETY.arm_memory_steps} steps, m")
    roll.add_argument("--no-guard-tool", action="store_true",
                      help="the arm's rule watches the arm's blind links only, not the tool")
    roll.add_argument("--tool-clearance", type=float, default=ACTING_SAFETY.tool_clearance,
                      help="the clearance the arm's rule keeps the tool at, m")
    roll.add_argument("--held-draw-std", type=float, default=HELD_DRAW_STD,
                      help="where the arm was held, draw the next action with at least this standard deviation per "
                           "action dimension (actions lie in [-1, 1]; 0: the policy's own)")
    roll.add_argument("--start-clearance", type=float, default=0.0,
                      help="random worlds: keep the robot's start this far from every obstacle, m (default 0: free of "
                           "collision only; the authors' generator kept 0.05)")
    roll.add_argument("--split", choices=EVALUATION_SPLITS, default="validation",
                      help="seed split of random worlds (validation: for tuning; test: for quoting, never tuned on)")
    roll.add_argument("--seed", type=int, default=None,
                      help="seed of the first random world, within --split (default: the split's first)")
    roll.add_argument("--json", action="store_true", help="print one JSON line")

    export = sub.add_parser("export", help="copy a run's model (or latest checkpoint) to a shipped file + "
                                           "JSON, or write it as one ONNX graph")
    export_source = export.add_mutually_exclusive_group(required=True)
    export_source.add_argument("--run", help="run directory (its best.zip, else the newer of model.zip and "
                                              "checkpoint.zip) or bundle .zip")
    export_source.add_argument("--model", help="a bundle .zip, or a robot name for its shipped policy "
                                                "(models/ROBOT.zip)")
    export.add_argument("--to", help="target .zip, e.g. models/ur5.zip")
    export.add_argument("--onnx", help="target .onnx: the deterministic action, the observation's "
                                       "normalisation folded in")

    clone = sub.add_parser("clone", help="fit a run's checkpoint to a scripted expert's demonstrations")
    clone.add_argument("--run", required=True, help="run directory holding checkpoint.zip")
    clone.add_argument("--kind", required=True, choices=EXPERTS,
                       help="the world kind whose expert to clone: shelf (KR16; broad runs), goal_slot or goal_cover (UR5), goal_box (broad runs)")
    clone.add_argument("--episodes", type=int, default=CloneConfig.episodes, help="expert-world episodes per round")
    clone.add_argument("--rounds", type=int, default=CloneConfig.rounds)
    clone.add_argument("--anchor-episodes", type=int, default=CloneConfig.anchor_episodes,
                       help="episodes in the other training worlds that keep their behaviour")
    clone.add_argument("--anchor-tolerance", type=float, default=None,
                       help="goal tolerance of those episodes, m (default: the run's curriculum goal size)")
    clone.add_argument("--eval-episodes", type=int, default=CloneConfig.eval_episodes,
                       help="expert-world episodes that measure the actor before and after")

    distil = sub.add_parser("distill", help="distil a privileged teacher (train --privileged) into a policy that "
                                            "sees only its rays (DAgger); fine-tune it with train --resume")
    distil.add_argument("--teacher", required=True, type=Path, help="the teacher's model.zip or checkpoint.zip")
    distil.add_argument("--out", required=True, type=Path, help="run directory of the student")
    distil.add_argument("--steps", type=int, default=DistillConfig.steps, help="environment steps in all")
    distil.add_argument("--teacher-steps", type=int, default=DistillConfig.teacher_steps,
                        help="steps over which the teacher's share of the driving falls from 1 to 0")
    distil.add_argument("--envs", type=int, default=DistillConfig.envs, help="worlds stepped at once")
    distil.add_argument("--resume", action="store_true", help="continue an interrupted distillation in --out")

    robots = sub.add_parser("robots", help="the robots: URDF package, joints, shipped policy, Gymnasium id")
    robots.add_argument("--json", action="store_true", help="print one JSON list")

    rays = sub.add_parser("rays", help="the 129 rays a real arm mounts or emulates: order, mount, frame, origin, direction")
    rays.add_argument("--robot", default="ur5", help=ROBOT_HELP)
    rays.add_argument("--json", action="store_true", help="print one JSON list, one object per ray")
    rays.add_argument("--plot", type=Path, default=None, metavar="PNG", help="also draw the paper's 129 in the flange frame to this file")
    rays.add_argument("--tip-back", action="store_true",
                      help="also the 24 tip-back rays (129-152) that a policy of the default recipe reads")
    rays.add_argument("--slanted", action="store_true",
                      help="also the 32 slanted rays, after the tip-back ones where those are listed")
    rays.add_argument("--arm-rays", action="store_true",
                      help="also the 64 rays round the upper arm and the forearm, after the slanted ones")

    demo = sub.add_parser("demo", help="a scripted episode on exp1, drawn to a PNG")
    demo.add_argument("--scenario", default="exp1")
    demo.add_argument("--out", default="demo", help="output directory")
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    from rayreach.scenarios import ScenarioError

    try:
        if args.command == "show":
            return _show(args, _pick_scenario(args, parser))
        if args.command == "bench-env":
            return _bench(args)
        if args.command == "evaluate":
            return _evaluate(args)
        if args.command == "bench-planners":
            return _bench_planners(args)
        if args.command == "bench-goals":
            from rayreach.evaluate.executor import bench_goals

            counts = tuple(int(n) for n in args.more_seeds.split(","))
            record = bench_goals(args.suite, args.robot, args.worlds, args.first_seed, counts, args.from_home)
            if args.json:
                print(json.dumps(record))
                return 0
            for n, r in record["counts"].items():
                print(f"more seeds {n:>5}: {r['statuses']}  {r['ms_per_world']} ms/world")
            return 0
        if args.command == "bench-acting":
            return _bench_acting(args)
        if args.command == "demo":
            return _demo(args)
        if args.command == "robots":
            return _robots(args)
        if args.command == "rays":
            return _rays(args)
        if args.command == "train":
            return _train(args, argv)
        if args.command == "bench-train":
            return _bench_train(args)
        if args.command == "sweep":
            return _sweep(args, argv)
        if args.command == "compare-recipes":
            return _compare_recipes(args)
        if args.command == "export":
            from rayreach.learning.export import export_bundle

            if not (args.to or args.onnx):
                parser.error("export: give --to (a bundle copy) and/or --onnx (an ONNX graph)")
            source = _model(args.model) if args.model else args.run
            if args.to:
                written = export_bundle(source, args.to)
                for path in written:
                    print(f"wrote {path}")
                source = written[0]  # the ONNX graph is then the copy's, whatever a run writes meanwhile
            if args.onnx:
                from rayreach.learning.onnx_export import export_onnx

                print(f"wrote {export_onnx(source, args.onnx)}")
            return 0
        if args.command == "rollout":
            return _rollout(args, _pick_scenario(args, parser))
        if args.command == "clone":
            return _clone(args)
        if args.command == "distill":
            return _distill(args, argv)
    except KeyboardInterrupt as exc:
        print(f"rayreach {args.command}: {exc or 'interrupted'}", file=sys.stderr)
        return 130
    except (ScenarioError, ValueError, FileNotFoundError) as exc:
        print(f"rayreach {args.command}: {exc}", file=sys.stderr)
        return 2
    parser.error(f"unknown command {args.command}")
    return 2


def _show(args: argparse.Namespace, scenario: str) -> int:
    from rayreach.env.reach import ReachEnv
    from rayreach.evaluate.render import draw_scene

    if args.gui:
        env = ReachEnv(scenario=scenario, render_mode="human")
        env.reset(seed=args.seed)
        print("PyBullet GUI open; press Enter to close.")
        input()
        env.close()
        return 0
    if args.planner is None:
        if args.video:
            raise ValueError("--video needs a --planner to run (e.g. --planner drl)")
        env = ReachEnv(scenario=scenario)
        env.reset(seed=args.seed)
        name = env.scenario.name if env.scenario else "scene"
        out = draw_scene(env, args.out or f"{name}.png")
        env.close()
        print(f"wrote {out}")
        return 0
    from rayreach.evaluate.executor import Executor
    from rayreach.planners import make_planner
    from rayreach.evaluate.render import write_video

    with Executor(scenario) as ex:
        planner = make_planner(args.planner, ex.robot, model=_model(args.model) if args.model else None)
        record = ex.run(planner, args.seed)
        print(f"{args.planner} on {scenario}: {record.outcome}, path {record.path_length:.3f} m, "
              f"planning {record.planning_time:.3f} s, motion {record.motion_time:.2f} s")
        if args.video:
            print(f"wrote {write_video(ex, record, args.video)}")
        name = ex.env.scenario.name
        ex.reset(args.seed)  # the picture: the arm and its rays at the start, the path drawn over it
        out = draw_scene(ex.env, args.out or f"{name}-{args.planner}.png", trajectory=record.ee_path,
                         title=f"{name}: {args.planner}, {record.outcome}, path {record.path_length:.2f} m")
        print(f"wrote {out}")
    return 0


def _bench(args: argparse.Namespace) -> int:
    from rayreach.evaluate.bench import bench_batched, bench_env, step_breakdown

    if args.batched is not None:
        if args.batched < 1:
            raise ValueError(f"--batched takes the number of worlds (>= 1), got {args.batched}")
        batched = bench_batched(args.robot, args.scenario, args.batched, steps=args.steps, rounds=args.rounds)
        if args.json:
            print(json.dumps(batched))
            return 0
        for name, sps in batched["steps_per_s"].items():
            print(f"{name:>8}: {sps:9.0f} world steps/s")
        print(f"speedup of {args.batched} batched worlds over one env: {batched['speedup']:.1f}x "
              f"({batched['steps']} world steps each)")
        for stage, us in batched["us_per_world_step"].items():
            print(f"{stage:>18}: {us:6.2f} us per world step")
        for name, ms in batched["ms_per_reset"].items():
            print(f"{name:>8}: {ms:6.2f} ms per random-world reset")
        return 0
    result = bench_env(args.robot, args.scenario, steps=args.steps, rounds=args.rounds)
    record: dict = {
        "robot": args.robot,
        "scenario": args.scenario,
        "steps": result.steps,
        "steps_per_s": {k: round(v, 1) for k, v in result.steps_per_s.items()},
        "default_backend": "numpy",
        "speedup": round(result.speedup, 3),
    }
    if args.breakdown:
        record["us_per_call"] = step_breakdown(args.robot, args.scenario)
        record["us_per_call"]["whole_step"] = round(1e6 / result.steps_per_s["numpy"], 1)
    if args.json:
        print(json.dumps(record))
        return 0
    for backend, sps in record["steps_per_s"].items():
        print(f"{backend:>7}: {sps:8.0f} steps/s")
    print(f"speedup of numpy over rayTestBatch: {record['speedup']:.2f}x ({result.steps} steps each)")
    for part, us in record.get("us_per_call", {}).items():
        print(f"{part:>22}: {us:7.1f} us")
    return 0


def _evaluate(args: argparse.Namespace) -> int:
    from rayreach.evaluate import EvaluationConfig, evaluate, parse_experiments, write_report
    from rayreach.evaluate.report import summarise
    from rayreach.evaluate.runner import random_experiment

    default_planners = "drl,drl-alone" if args.suite else EVAL_PLANNERS
    planners = _names(args.planners or default_planners)
    runs = args.runs
    if args.suite:
        obstacles = None if args.obstacles == EvaluationConfig.obstacles else args.obstacles
        experiments = tuple(random_experiment(r, obstacles, args.split or "test", args.suite)
                            for r in _names(args.robot))
        runs = args.episodes or 500
    else:
        for option, value in (("--obstacles", args.obstacles), ("--split", args.split)):
            if value is not None:
                raise ValueError(f"{option} applies to --suite random or broad (the experiments' scenes are fixed)")
        experiments = parse_experiments(args.experiments)
    models = tuple((robot, str(_model(path))) for robot, path in (("ur5", args.model_ur5), ("kr16", args.model_kr16))
                   if path)
    config = EvaluationConfig(experiments, planners, runs=runs, time_limit=args.time_limit,
                              run_timeout=args.run_timeout, smooth=args.smooth, replan=args.replan, models=models)
    if args.workers is not None:
        from dataclasses import replace

        config = replace(config, workers=args.workers)
    if not args.report_only and args.ray is not None:
        from rayreach.evaluate.ray_runner import evaluate_on_ray

        evaluate_on_ray(config, args.out, address=None if args.ray == "local" else args.ray, actors=args.workers)
    elif not args.report_only:
        evaluate(config, args.out)
    written = write_report(args.out)
    if args.suite:
        from rayreach.evaluate.store import ResultsStore

        store = ResultsStore(written["table"].parent / "results.db")
        rows = store.rows()
        store.close()
        for (experiment, planner), s in sorted(summarise(rows).items()):
            rates = ", ".join(f"{k} {v / s['runs']:.1%}" for k, v in s["outcomes"].items())
            share = "" if s["policy_share"] is None else f"; policy chose {s['policy_share']:.1%} of steps"
            print(f"{experiment} {planner}: {s['runs']} worlds: {rates}{share}")
    else:
        print(written["table"].read_text())
    for kind, path in written.items():
        print(f"{kind}: {path}")
    return 0


def _bench_acting(args: argparse.Namespace) -> int:
    from rayreach.evaluate.bench_acting import bench_acting

    record = bench_acting(_model(args.model), args.episodes, args.obstacles, args.split, progress=not args.json)
    if args.json:
        print(json.dumps(record))
        return 0
    print(f"{'variant':>24} {'us/step':>9} {'ratio':>7} {'steps':>7}")
    for name, r in record.items():
        print(f"{name:>24} {r['us_per_step']:9.1f} {r['ratio']:7.3f} {r['steps']:7d}")
    return 0


def _bench_planners(args: argparse.Namespace) -> int:
    from rayreach.evaluate.bench import bench_planners
    from rayreach.planners import SAMPLING_PLANNERS
    from rayreach.planners.ompl_peer import ompl_available

    if args.planners:
        names = list(_names(args.planners))
    else:
        names = [p for p in SAMPLING_PLANNERS if ompl_available() or not p.startswith("ompl")]
    record = bench_planners(args.scenario, args.runs, names, args.time_limit, progress=not args.json)
    if args.json:
        print(json.dumps(record))
        return 0
    print(f"{args.scenario}: {args.runs} runs per planner, time limit {args.time_limit:g} s; "
          f"collision checks: {record['checks_per_s']:,.0f}/s")
    print(f"{'planner':>16} {'solved':>7} {'success':>8} {'median plan s':>14} {'median path m':>14}")
    for name, r in record["planners"].items():
        t = "/" if r["planning_time_median_s"] is None else f"{r['planning_time_median_s']:.4f}"
        length = "/" if r["path_length_median_m"] is None else f"{r['path_length_median_m']:.3f}"
        print(f"{name:>16} {r['solved']:>7} {r['success']:>8} {t:>14} {length:>14}")
    return 0


def _names(text: str) -> tuple[str, ...]:
    """A comma-separated option's names, blanks dropped ('' gives none)."""
    return tuple(name.strip() for name in text.split(",") if name.strip())


def _speed_range(text: str) -> tuple[float, float]:
    """``LOW,HIGH`` in m/s; ``RandomWorldConfig`` checks the bounds."""
    try:
        low, high = (float(v) for v in text.split(","))
    except ValueError:
        raise ValueError(f"a speed range is LOW,HIGH in m/s (e.g. 0.03,0.08), got {text!r}") from None
    return low, high


def _train(args: argparse.Namespace, argv: Sequence[str] | None) -> int:
    from dataclasses import replace

    from rayreach.learning.curriculum import GoalSizeParams, ObstacleParams
    from rayreach.robots import get_robot
    from rayreach.learning.bundles import read_bundle_meta
    from rayreach.learning.selection import BEST
    from rayreach.learning.clone_stage import train_with_clone
    from rayreach.learning.train import CHECKPOINT, RECIPES, recipe, with_envs

    robot = get_robot(args.robot).name
    out = args.out or f"runs/{robot}-{args.recipe}"
    saved = (read_bundle_meta(Path(out) / CHECKPOINT)[0].get("config", {})
             if args.resume and (Path(out) / CHECKPOINT).exists() else {})
    suite = args.suite or saved.get("suite")  # a resumed run's defaults are its suite's
    config = recipe(args.recipe, robot=robot, seed=args.seed, **({} if suite is None else {"suite": suite}))
    if args.timesteps is not None:
        config = replace(config, timesteps=args.timesteps)
    envs = args.envs if args.envs is not None else saved.get("envs")  # a resumed run's own: the checks see it
    if envs is not None:
        config = with_envs(config, envs)
    if args.workers is not None:
        config = replace(config, workers=args.workers)
    if args.target_kl is not None:
        config = replace(config, target_kl=args.target_kl or None)
    if args.separate_features:
        config = replace(config, share_features=False)
    if args.starts is not None:
        config = replace(config, starts=args.starts)
    if args.start_decisions is not None:
        config = replace(config, start_decisions=args.start_decisions)
    if args.decision_period is not None:
        config = replace(config, decision_period=args.decision_period)
    if args.action_std_init is not None:
        started = saved.get("action_std_init", RECIPES["baseline"].action_std_init)  # config_from_meta's rule
        if args.resume and args.action_std_init != started:
            raise ValueError(f"--action-std-init sets the noise a run starts with; this run started with "
                             f"{started:g} and keeps its learned noise: give {started:g} or leave it out")
        config = replace(config, action_std_init=args.action_std_init)
    from rayreach.sim.sensors import EXTRA_RAYS

    rays = {name: getattr(args, name) for name in EXTRA_RAYS if getattr(args, name) is not None}
    if args.goal_sight is not None:
        rays["goal_sight"] = args.goal_sight
    if args.privileged:
        rays["privileged"] = True
    if rays:
        config = replace(config, observation=replace(config.observation, **rays))
    overrides: dict = {"envs": args.envs} if args.envs is not None else {}
    for name in ("checkpoint_every", "collision_weight", "out_of_bounds_weight", "collision_margin",
                 "progress_weight", "proximity_weight", "shield_weight", "progress_around_obstacles",
                 "validate_every", "validate_worlds"):
        if getattr(args, name) is not None:
            overrides[name] = getattr(args, name)
    if args.clone_at is not None:
        overrides["clone_at"] = args.clone_at
        if args.clone_at == 0:
            overrides["clone_kinds"] = ()
    if args.clone_kinds is not None:
        overrides["clone_kinds"] = _names(args.clone_kinds)
        overrides.setdefault("clone_at", config.clone_at if overrides["clone_kinds"] else 0)
    if args.imitation_steps is not None:
        overrides["imitation_steps"] = args.imitation_steps
    if args.extra_kinds is not None:
        overrides["extra_kinds"] = _names(args.extra_kinds)
    if args.cover_speed is not None:
        overrides["cover_speed"] = _speed_range(args.cover_speed)
    given = [flag for flag, value in (("--obstacles", args.obstacles), ("--obstacle-mix", args.obstacle_mix),
                                      ("--obstacle-curriculum", args.obstacle_curriculum or None)) if value is not None]
    if len(given) > 1:
        raise ValueError(f"{' and '.join(given)} each set the obstacle counts (one count, 1 to N mixed, "
                         "the curriculum): give one")
    if args.obstacle_curriculum:
        overrides["obstacles"] = ObstacleParams()
    if args.obstacles is not None:
        overrides["obstacles"] = ObstacleParams(start=args.obstacles, minimum=args.obstacles, maximum=args.obstacles)
    if args.obstacle_mix is not None:
        if args.obstacle_mix < 1:
            raise ValueError(f"--obstacle-mix must be >= 1, got {args.obstacle_mix}")
        n = args.obstacle_mix
        overrides["obstacles"] = ObstacleParams(start=n, minimum=n, maximum=n, mix=True)
    if args.goal_size is not None:
        config = replace(config, goal=GoalSizeParams(rho=args.goal_size, e_zeta=2**62))
    if args.true_goal_share is not None:
        overrides["true_goal_share"] = args.true_goal_share
    if args.acting_layers:
        overrides["acting_layers"] = True
    if args.gamma is not None:
        if not 0 < args.gamma < 1:
            raise ValueError(f"--gamma must lie in (0, 1), got {args.gamma}")
        overrides["gamma"] = args.gamma
    if args.learning_rate is not None:
        if not args.learning_rate > 0:
            raise ValueError(f"--learning-rate must be > 0, got {args.learning_rate}")
        overrides["learning_rate"] = args.learning_rate
    config = replace(config, **overrides)
    command = _command_line(argv)
    path = train_with_clone(config, out, resume=args.resume, command=command, resume_overrides=overrides,
                             critic_warmup=args.critic_warmup, freeze_features=args.freeze_features)
    print(f"model: {path}")
    best = read_bundle_meta(path)[0]["state"].get("best")
    if best:
        print(f"best on {best['worlds']} validation worlds: {path.parent / BEST} "
              f"({best['timesteps']:,} steps, success {best['success_rate']:.1%}, collisions {best['collision_rate']:.1%})")
    return 0


def _sweep(args: argparse.Namespace, argv: Sequence[str] | None) -> int:
    from dataclasses import replace

    from rayreach.learning.sweep import parse_seeds, parse_setting, plan_trials, sweep
    from rayreach.learning.train import recipe
    from rayreach.robots import get_robot

    config = recipe(args.recipe, robot=get_robot(args.robot).name, checkpoint_every=args.checkpoint_every)
    if args.timesteps is not None:
        config = replace(config, timesteps=args.timesteps)
    setting = parse_setting(args.setting, config) if args.setting else None
    trials = plan_trials(config, args.out, parse_seeds(args.seeds), setting)
    for trial in trials:
        print(f"{trial.name}: {trial.out}")

    def report(result) -> None:
        outcome = result.error or f"model {result.model} ({result.seconds:.0f} s)"
        print(f"{result.trial.name} ({result.state}): {outcome}", flush=True)

    command = _command_line(argv)
    results = sweep(trials, ray_address=args.ray, use_ray=args.ray is not None, cpus=args.cpus,
                    command=command, report=report)
    failed = [r.trial.name for r in results if r.error]
    if failed:
        print(f"rayreach sweep: {len(failed)} of {len(results)} trials failed: {', '.join(failed)}", file=sys.stderr)
        return 1
    return 0


def _bench_train(args: argparse.Namespace) -> int:
    from rayreach.evaluate.bench_train import bench_train
    from rayreach.robots import get_robot

    if not args.seconds > 0:
        raise ValueError(f"--seconds must be > 0, got {args.seconds}")
    record = bench_train(get_robot(args.robot).name, args.seconds)
    if args.json:
        print(json.dumps(record))
        return 0
    print(f"{record['robot']}: {record['seconds']:g} s per recipe after a warm-up; speedup {record['speedup']:.2f}")
    print(f"{'recipe':>10} {'samples/s':>10} {'collect s':>10} {'update s':>9}")
    for name, rate in record["samples_per_s"].items():
        phases = record["phases"][name]
        print(f"{name:>10} {rate:10.0f} {phases['collect_s']:10.1f} {phases['update_s']:9.1f}")
    return 0


def _compare_recipes(args: argparse.Namespace) -> int:
    from rayreach.evaluate.compare_recipes import compare_recipes
    from rayreach.robots import get_robot

    variants = _names(args.variants)
    summary = compare_recipes(get_robot(args.robot).name, args.minutes, args.out, episodes=args.episodes,
                              variants=variants, goal=args.goal, obstacles=args.obstacles, jobs=args.jobs)
    for name, data in summary["recipes"].items():
        v = data["validation"]
        print(f"{name:>17}: {data['timesteps']:>10,} steps in {data['wall_time_s']:.0f} s; validation "
              f"success {v['success_rate']:.1%}, collisions {v['collision_rate']:.1%}")
    print(f"wrote {args.out}/curves.png and summary.json")
    return 0


def acting_from_args(args: argparse.Namespace):
    """The ``ActingConfig`` that ``rollout``'s flags ask for."""
    from rayreach.acting import LAYERS, ActingConfig
    from rayreach.acting.detour import Detour
    from rayreach.acting.final_approach import FinalApproach
    from rayreach.acting.shield import SafetyLayer

    safety = SafetyLayer(args.workspace_guard, args.ray_shield, args.slide, args.memory_steps, args.arm_clearance,
                         guard_tool=not args.no_guard_tool, tool_clearance=args.tool_clearance,
                         arm_rays=args.guard_arm_rays)
    config = ActingConfig(final_approach=FinalApproach(args.final_approach_radius, stall_steps=args.stall_steps,
                                                       turn=not args.no_turn, give_way=not args.no_give_way),
                          safety=safety, detour=Detour(stall_steps=args.detour_steps), held_draw_std=args.held_draw_std)
    off = LAYERS if args.policy_alone else [layer for layer in LAYERS if getattr(args, f"no_{layer}")]
    return config.without(*off)


def _rollout(args: argparse.Namespace, scenario: str) -> int:
    from rayreach.evaluate.rollout import rollout, rollout_batched

    acting = acting_from_args(args)
    if args.batched:
        if not args.policy_alone or args.stochastic or scenario not in WORLD_SUITES:
            raise ValueError("--batched steps the policy alone (--policy-alone), deterministic, on drawn worlds "
                             f"({', '.join(WORLD_SUITES)}); got {scenario}"
                             + (", --stochastic" if args.stochastic else "")
                             + ("" if args.policy_alone else ", acting layers on"))
        summary = rollout_batched(_model(args.model), episodes=args.episodes, goal_tolerance=args.tolerance,
                                  n_obstacles=args.obstacles, seed=args.seed, start_clearance=args.start_clearance,
                                  split=args.split, suite=scenario)
    else:
        summary = rollout(_model(args.model), scenario, episodes=args.episodes, deterministic=not args.stochastic,
                          goal_tolerance=args.tolerance, n_obstacles=args.obstacles, progress=not args.json,
                          acting=acting, start_clearance=args.start_clearance, seed=args.seed, split=args.split)
    if args.json:
        print(json.dumps({"scenario": scenario, **summary.to_dict()}))
        return 0
    mode = ("deterministic" if summary.deterministic else "stochastic") + ", " + (
        " + ".join(summary.acting_layers) or "policy alone")
    print(f"{scenario}: {summary.episodes} episodes ({mode}), success {summary.success_rate:.1%}, "
          f"collisions {summary.collision_rate:.1%}, mean path {summary.path_length_mean:.3f} m, "
          f"mean steps {summary.steps_mean:.0f}")
    print("outcomes: " + ", ".join(f"{k.replace('_', ' ')} {v}" for k, v in summary.outcomes.items()))
    print("steps by source: " + ", ".join(f"{k.replace('_', ' ')} {v:.1%}" for k, v in summary.acting_share.items()))
    if summary.held_by:
        print("steps held by: " + ", ".join(f"{k.replace('_', ' ')} {v:.1%}" for k, v in summary.held_by.items()))
    for kind, counts in summary.by_kind.items():  # random worlds: which kinds of world fail
        n = counts["episodes"]
        print(f"  {kind:>13}: {n:4d} worlds, " + ", ".join(
            f"{k.replace('_', ' ')} {counts[k] / n:.0%}" for k in counts if k != "episodes"))
    return 0


def _command_line(argv: Sequence[str] | None) -> str:
    """The command as typed, for a run's metadata."""
    return "rayreach " + " ".join(sys.argv[1:] if argv is None else argv)


def _distill(args: argparse.Namespace, argv: Sequence[str] | None) -> int:
    from rayreach.learning.distill import DistillConfig, distill

    config = DistillConfig(steps=args.steps, teacher_steps=args.teacher_steps, envs=args.envs)
    command = _command_line(argv)
    checkpoint = distill(args.teacher, args.out, config, resume=args.resume, command=command)
    print(f"student written to {checkpoint}; fine-tune it with: rayreach train --robot ROBOT --out {args.out} "
          "--resume --timesteps N")
    return 0


def _clone(args: argparse.Namespace) -> int:
    from rayreach.learning.demonstrations import CloneConfig, clone_into_checkpoint

    config = CloneConfig(episodes=args.episodes, rounds=args.rounds, anchor_episodes=args.anchor_episodes,
                         anchor_tolerance=args.anchor_tolerance,
                         eval_episodes=args.eval_episodes)
    report = clone_into_checkpoint(args.run, args.kind, config)
    before, after = report["expert_worlds"]["before"], report["expert_worlds"]["after"]
    print(f"{args.kind} worlds: success {before['success']:.0%} -> {after['success']:.0%}, "
          f"collisions {before['collision']:.0%} -> {after['collision']:.0%}; "
          f"other worlds: success {report['other_worlds']['before']['success']:.0%} -> "
          f"{report['other_worlds']['after']['success']:.0%} ({report['wall_time_s']:.0f} s)")
    return 0


def _source_package(urdf: Path) -> str | None:
    """The installed distribution whose files hold ``urdf``: the robot's source as pip names
    it, read from the installation rather than restated beside each spec."""
    from importlib import metadata

    target = Path(urdf).resolve()
    for dist in metadata.distributions():
        for file in dist.files or ():
            if file.name == target.name and Path(str(dist.locate_file(file))).resolve() == target:
                return dist.metadata["Name"]
    return None


def _robots(args: argparse.Namespace) -> int:
    from rayreach import ENV_IDS
    from rayreach.planners.drl import MODELS_DIR, shipped_robots

    shipped = shipped_robots()
    rows = []
    for name, spec in ROBOTS.items():
        try:
            package = _source_package(spec.urdf())
        except FileNotFoundError as exc:  # the URDF's package is not installed
            package = f"missing: {exc}"
        env_id = next((i for i in ENV_IDS if i.lower() == f"rayreach/reach-{name}-v0"), None)
        rows.append({"name": name, "package": package, "dof": spec.n_joints,
                     "kinematics": "URDF joints" if spec.dh is None else "DH table", "shipped_policy": name in shipped,
                     "policy": str(MODELS_DIR / f"{name}.zip") if name in shipped else None, "env_id": env_id})
    if args.json:
        print(json.dumps(rows))
        return 0
    print(f"{'robot':<8} {'URDF package':<20} {'dof':>3}  {'kinematics':<12} {'shipped policy':<14}  Gymnasium id")
    for r in rows:
        print(f"{r['name']:<8} {r['package'] or '?':<20} {r['dof']:>3}  {r['kinematics']:<12} "
              f"{'yes' if r['shipped_policy'] else 'no':<14}  {r['env_id'] or '-'}")
    return 0


def _rays(args: argparse.Namespace) -> int:
    from rayreach.robots import get_robot
    from rayreach.sim.sensors import EXTRA_RAYS, RAY_RANGE, layout_rows

    spec = get_robot(args.robot)
    rows = layout_rows(spec, [name for name in EXTRA_RAYS if getattr(args, name)])
    if args.plot is not None:
        from rayreach.evaluate.ray_layout import ray_layout_figure

        print(f"layout drawn to {ray_layout_figure(spec, args.plot)}", file=sys.stderr)
    if args.json:
        print(json.dumps(rows))
        return 0
    print(f"{spec.name}: {len(rows)} rays, range {RAY_RANGE} m; origin and direction in the flange frame "
          f"({spec.flange_link}, chain frame {spec.n_joints}, z along the tool), or, for a mount elsewhere, in "
          "the chain frame it moves with (docs/kinematics.md; --json adds each ray in its mount's own frame)")
    print(f"{'ray':>3}  {'sensor':<10} {'mount link':<14} {'frame':>5}  {'origin (m)':<26} direction")
    for r in rows:
        origin = " ".join(f"{v:+.3f}" for v in r["origin_chain"])
        direction = " ".join(f"{v:+.3f}" for v in r["direction_chain"])
        frame = "flange" if r["origin_flange"] is not None else f"{r['frame']}"
        print(f"{r['index']:>3}  {r['sensor']:<10} {r['link']:<14} {frame:>6} {origin:<26} {direction}")
    return 0


def _demo(args: argparse.Namespace) -> int:
    from rayreach.evaluate.demo import scripted_episode

    summary = scripted_episode(args.scenario, args.out)
    print(
        f"{args.scenario}: scripted episode, {summary.steps} steps, success={summary.success}, "
        f"collision={summary.collision}, path {summary.path_length:.3f} m, return {summary.total_reward:.2f}"
    )
    print(f"picture: {summary.picture}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
