"""The ``simlan-run`` console script: a cached ``--help`` answers before the app is imported."""

from __future__ import annotations

import sys

from simlan_data.apps.help_cache import serve_cached_help
from simlan_data.apps.signals import exit_on_early_signal


def simlan_run() -> None:
    exit_on_early_signal()
    if serve_cached_help(sys.argv[1:]):
        return
    from simlan_data.apps.run import main

    main()
