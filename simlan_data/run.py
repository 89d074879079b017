"""``python -m simlan_data.run``: simulate a scenario, record it, report it (a Hydra app).

The public name of ``python -m simlan_data.run``; the application is :mod:`simlan_data.apps.run`.
"""

from __future__ import annotations

if __name__ == "__main__":  # SIGTERM while the app is imported: one line, exit 143
    from simlan_data.apps.signals import exit_on_early_signal

    exit_on_early_signal()

from simlan_data.apps.run import cli, main

__all__ = ["cli", "main"]

if __name__ == "__main__":
    cli()
