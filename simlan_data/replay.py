"""``python -m simlan_data.replay RECORDING``: inspect and replay a recording without the simulator.

The public name of ``python -m simlan_data.replay``; the application is :mod:`simlan_data.apps.replay`.
"""

from __future__ import annotations

from simlan_data.apps.replay import cli, main

__all__ = ["cli", "main"]

if __name__ == "__main__":
    cli()
