"""``python -m simlan_data.recover RUN_OR_RECORDING``: repair the recording of a crashed run.

    python -m simlan_data.recover recordings/my_run            rebuild summary and metadata.yaml
    python -m simlan_data.recover recordings/my_run --dry-run  say what is readable, write nothing
    python -m simlan_data.recover recordings/my_run --json     the report as JSON (for scripts)

Keeps every complete MCAP chunk (a crash loses at most ``recording.flush_period_s`` of simulated
time), keeps the damaged original as ``recording.mcap.damaged``, marks the run directory
``INCOMPLETE`` and says what was recovered and what was lost. Exit 0 when done (or nothing to
do), 2 when the input is not a recoverable recording, 1 when writing failed.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from simlan_data.apps.cli import run_cli
from simlan_data.recording.recover import recover


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m simlan_data.recover",
        description="Repair the recording of a crashed run: keep every complete chunk, rebuild the MCAP "
        "summary and metadata.yaml, say what was lost.",
    )
    parser.add_argument("recording", type=Path, help="run directory or recording directory")
    parser.add_argument("--dry-run", action="store_true", help="report what is readable; write nothing")
    parser.add_argument("--json", action="store_true", help="print the report as JSON")
    parser.add_argument(
        "--force", action="store_true", help="recover even though the RUNNING marker's process is alive"
    )
    parser.add_argument("--debug", action="store_true", help="show tracebacks")
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    report = recover(args.recording, dry_run=args.dry_run, force=args.force)
    if args.json:
        print(json.dumps({**report.summary(), "written": report.written}, indent=2))
    else:
        print("\n".join(report.lines()))
    return 0


def cli() -> None:
    """The command line: run :func:`main`, turning errors into one line and an exit code."""
    run_cli(lambda: sys.exit(main()))


if __name__ == "__main__":
    cli()
