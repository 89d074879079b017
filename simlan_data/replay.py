"""``python -m simlan_data.replay RECORDING``: inspect and replay a recording without the simulator.

python -m simlan_data.replay RECORDING --info        ros2-bag-info-like summary
"""

from __future__ import annotations

import argparse
import sys

from .cli import run_cli
from .errors import EXIT_BAD_INPUT
from .recording.reader import RecordingReader


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m simlan_data.replay",
        description="Inspect a simlan_data recording (a ROS 2 bag in MCAP storage) without the simulator.",
    )
    parser.add_argument("recording", help="recording directory (or its run directory, or metadata.yaml)")
    parser.add_argument("--info", action="store_true", help="print a summary like `ros2 bag info` and exit")
    parser.add_argument("--debug", action="store_true", help="show tracebacks")
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    with RecordingReader(args.recording) as reader:
        if args.info:
            print(reader.summary())
            return 0
        parser.print_usage(sys.stderr)
        sys.stderr.write("error: nothing to do; give --info\n")
        return EXIT_BAD_INPUT


if __name__ == "__main__":
    run_cli(lambda: sys.exit(main()))
