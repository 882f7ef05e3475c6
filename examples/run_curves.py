"""Training runs side by side: success in training and on the validation worlds, by decisions.

Each run directory holds ``curve.csv`` (the last 200 training episodes after every update) and,
where the run chose its checkpoint on validation worlds, ``validation.csv``. A run resumed
from a copy of another shares its curve up to the copy; a clone of scripted demonstrations
(``rayreach clone``, its ``clone-KIND.json`` in the run directory) is marked where it was made.

    python examples/run_curves.py models/train-ur5-broad-v2 models/train-ur5-broad-clone \\
        --until 12815360 --out broad-clone.png
"""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # headless: the figure only goes to a file
import matplotlib.pyplot as plt  # noqa: E402

from rayreach.learning.selection import read_validation  # noqa: E402

MODELS = Path(__file__).resolve().parents[1] / "models"


def curve_rows(run: Path) -> list[dict[str, float]]:
    """The rows of a run's curve.csv, as numbers."""
    with (run / "curve.csv").open(newline="") as handle:
        return [{k: float(v) for k, v in row.items() if v not in ("", None)} for row in csv.DictReader(handle)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="*", type=Path,
                        default=[MODELS / "train-ur5-broad-v2", MODELS / "train-ur5-broad-clone"])
    parser.add_argument("--until", type=float, default=float("inf"), help="last decision shown")
    parser.add_argument("--out", type=Path, default=Path("run_curves.png"))
    args = parser.parse_args()
    missing = [str(run) for run in args.runs if not (run / "curve.csv").is_file()]
    if missing:
        parser.error(f"no curve.csv in {', '.join(missing)}: give run directories of `rayreach train`")

    fig, (training, validation) = plt.subplots(1, 2, figsize=(11, 4), sharey=True)
    for run in args.runs:
        curve = [r for r in curve_rows(run) if r["timesteps"] <= args.until]
        checked = [r for r in read_validation(run) if r["timesteps"] <= args.until]
        line, = training.plot([r["timesteps"] / 1e6 for r in curve], [r["true_success_rate"] for r in curve],
                              lw=0.8, label=run.name)
        validation.plot([r["timesteps"] / 1e6 for r in checked], [r["success_rate"] for r in checked], "o-",
                        color=line.get_color(), label=run.name)
        for report in sorted(run.glob("clone-*.json")):
            cloned = json.loads(report.read_text())
            for ax in (training, validation):
                ax.axvline(cloned["timesteps"] / 1e6, color=line.get_color(), ls=":", lw=1)
        last = f"{curve[-1]['timesteps'] / 1e6:.1f} M" if curve else "none"
        print(f"{run}: curve to {last} decisions, {len(checked)} validations")
    training.set_title("training: reached the 1 cm goal (last 200 such episodes)")
    validation.set_title("alone on the validation worlds of its task")
    training.set_ylabel("success")
    for ax in (training, validation):
        ax.set_xlabel("decisions (millions); dotted: a clone")
        ax.set_ylim(-0.02, 1.02)
        ax.grid(alpha=0.3)
    validation.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)
    plt.close(fig)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
