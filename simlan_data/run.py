"""``python -m simlan_data.run``: simulate a scenario, record it, report it (a Hydra app).

The public name of ``python -m simlan_data.run``; the application is :mod:`simlan_data.apps.run`.
"""

from __future__ import annotations

if __name__ == "__main__":  # SIGTERM while the app is imported: one line, exit 143
    from simlan_data.apps.signals import exit_on_early_signal

    exit_on_early_signal()
    import sys

    from simlan_data.apps.help_cache import serve_cached_help

    if serve_cached_help(sys.argv[1:]):  # --help in 0.1 s, before the app's imports
        sys.exit(0)

from simlan_data.apps.run import cli, main

__all__ = ["cli", "main"]

if __name__ == "__main__":
    cli()
