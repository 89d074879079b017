"""Plot a robot's ground-truth path against its camera-based estimate, and print the error.

Reads `/ground_truth/poses` (the truth, map frame) and `/<ns>/pose_estimate` (the localizer's
fused estimate) from a recording, matches each estimate with the truth at the same stamp, and
saves a plot of both paths (matplotlib, headless).

    python examples/plot_trajectory.py RUN_OR_RECORDING --save trajectory.png [--agent robot_agent_1]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # no display needed
import matplotlib.pyplot as plt
import numpy as np

from simlan_data.errors import SimlanError
from simlan_data.recording.reader import RecordingReader


def read_paths(
    recording: Path, agent: str
) -> tuple[dict[int, tuple[float, float]], dict[int, tuple[float, float]]]:
    """{stamp_ns: (x, y)} of the truth and of the estimate of ``agent``."""
    truth: dict[int, tuple[float, float]] = {}
    estimate: dict[int, tuple[float, float]] = {}
    with RecordingReader(recording) as bag:
        for m in bag.messages(["/ground_truth/poses", f"/{agent}/pose_estimate"]):
            if m.topic == "/ground_truth/poses":
                for tf in m.msg.transforms:
                    if tf.child_frame_id.endswith(f"{agent}/base_link"):
                        truth[m.stamp_ns] = (tf.transform.translation.x, tf.transform.translation.y)
            else:
                p = m.msg.pose.pose.position
                estimate[m.stamp_ns] = (p.x, p.y)
    return truth, estimate


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    parser.add_argument("recording", type=Path, help="run directory or its recording/ folder")
    parser.add_argument("--agent", default="robot_agent_1")
    parser.add_argument("--save", type=Path, required=True, help="PNG file to write")
    args = parser.parse_args(argv)
    try:
        truth, estimate = read_paths(args.recording, args.agent)
    except SimlanError as err:
        print(f"error: {err}", file=sys.stderr)
        return err.exit_code
    common = sorted(set(truth) & set(estimate))
    if not common:
        print(
            f"error: no pose estimate of {args.agent} at a ground-truth stamp in {args.recording}; "
            "check --agent (a robot's namespace)",
            file=sys.stderr,
        )
        return 2
    err = np.array([np.subtract(estimate[t], truth[t]) for t in common])
    rmse_m = float(np.sqrt(np.mean(np.sum(err**2, axis=1))))
    xy_truth, xy_est = np.array([truth[t] for t in sorted(truth)]), np.array([estimate[t] for t in common])
    fig, ax = plt.subplots(figsize=(8, 4))
    ax.plot(xy_truth[:, 0], xy_truth[:, 1], "k-", label="ground truth")
    ax.plot(xy_est[:, 0], xy_est[:, 1], "r.", markersize=2, label="camera estimate")
    ax.set(xlabel="x (m, map)", ylabel="y (m, map)", title=f"{args.agent}: ATE xy RMSE {rmse_m * 100:.2f} cm")
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend()
    fig.savefig(args.save, dpi=100, bbox_inches="tight")
    print(f"{args.agent}: {len(common)} estimates, ATE xy RMSE {rmse_m * 100:.2f} cm; wrote {args.save}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
