"""``python -m simlan_data.evals SUITE``: run a V&V suite of ``evals/base.yaml`` and judge it.

The public name of ``python -m simlan_data.evals``; the application is :mod:`simlan_data.apps.evals`.
"""

from __future__ import annotations

from simlan_data.apps.evals import cli, main

__all__ = ["cli", "main"]

if __name__ == "__main__":
    cli()
