"""``python -m simlan_data.run``: simulate a scenario, record it, report it (a Hydra app).

The public name of ``python -m simlan_data.run``; the application is :mod:`simlan_data.apps.run`.
"""

from __future__ import annotations

from simlan_data.apps.run import cli, main

__all__ = ["cli", "main"]

if __name__ == "__main__":
    cli()
