"""How long one decision of a policy takes on one core: torch's forward pass, ``Policy.act``
(stable-baselines3's ``predict`` around it) and the ONNX graph through onnxruntime.

The policy decides once per control step, or once per decision period, so this is the cost
a real arm pays for it. Each model's three ways run in turn, ``--repeats`` times, in one
process: compare the columns of one run (this machine's speed drifts between days). Pin it
to one core for the figure a single-core controller would see:

    taskset -c 1 python examples/policy_latency.py --model ur5 --model models/train-ur5-v4/model.zip --out latency.png
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # headless: the figure only goes to a file
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402

from rayreach.learning.onnx_export import OnnxPolicy, export_onnx  # noqa: E402
from rayreach.learning.policy import load_policy  # noqa: E402
from rayreach.planners.drl import resolve_model  # noqa: E402

WAYS = ("torch forward pass", "Policy.act", "OnnxPolicy.act")


def _ms_per_call(call, calls: int) -> float:
    start = time.perf_counter()
    for _ in range(calls):
        call()
    return 1000 * (time.perf_counter() - start) / calls


def time_policy(model: str, calls: int, repeats: int, folder: Path) -> dict[str, list[float]]:
    """Milliseconds per call of each of ``WAYS`` for one observation, ``repeats`` times each."""
    policy = load_policy(resolve_model(model))
    graph = OnnxPolicy(export_onnx(policy, folder / f"{abs(hash(model))}.onnx"))
    obs = np.random.default_rng(0).normal(size=(1, policy.model.observation_space.shape[0])).astype(np.float32)
    tensor = torch.as_tensor(policy._normalized(obs))

    def forward():
        with torch.no_grad():
            policy.model.policy._predict(tensor, deterministic=True)

    ways = dict(zip(WAYS, (forward, lambda: policy.act(obs), lambda: graph.act(obs[0]))))
    for call in ways.values():
        call()  # first calls build caches
    times: dict[str, list[float]] = {way: [] for way in WAYS}
    for _ in range(repeats):
        for way, call in ways.items():
            times[way].append(_ms_per_call(call, calls))
    return times


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--model", action="append", help="ur5, kr16 or a model .zip (repeatable; default: ur5)")
    parser.add_argument("--calls", type=int, default=1000, help="calls per timing")
    parser.add_argument("--repeats", type=int, default=2, help="timings of each way, interleaved")
    parser.add_argument("--out", type=Path, required=True, help="bar chart, .png")
    args = parser.parse_args()
    models = args.model or ["ur5"]
    with tempfile.TemporaryDirectory() as folder:
        results = {model: time_policy(model, args.calls, args.repeats, Path(folder)) for model in models}
    print("| model | " + " | ".join(WAYS) + " |")
    print("|---|" + "---|" * len(WAYS))
    for model, times in results.items():
        cells = [f"{min(t):.2f}-{max(t):.2f} ms" for t in times.values()]
        print(f"| {model} | " + " | ".join(cells) + " |")
    fig, ax = plt.subplots(figsize=(7, 3.5))
    width = 0.8 / len(WAYS)
    for i, way in enumerate(WAYS):
        ax.bar(np.arange(len(models)) + i * width, [np.median(results[m][way]) for m in models], width, label=way)
    ax.axhline(1.0, color="grey", linestyle="--", linewidth=1, label="1 ms")
    ax.set_xticks(np.arange(len(models)) + width, [Path(m).parent.name or m for m in models])
    ax.set_ylabel("ms per decision (one observation)")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
