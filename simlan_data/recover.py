"""``python -m simlan_data.recover RUN_OR_RECORDING``: repair the recording of a crashed run.

The public name of ``python -m simlan_data.recover``; the application is :mod:`simlan_data.apps.recover`.
"""

from __future__ import annotations

from simlan_data.apps.recover import cli, main

__all__ = ["cli", "main"]

if __name__ == "__main__":
    cli()
