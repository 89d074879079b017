"""``python -m simlan_data.view RECORDING``: show a recording in Rerun.

The public name of ``python -m simlan_data.view``; the application is :mod:`simlan_data.apps.view`.
"""

from __future__ import annotations

from simlan_data.apps.view import cli, main

__all__ = ["cli", "main"]

if __name__ == "__main__":
    cli()
