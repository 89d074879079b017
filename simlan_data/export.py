"""``python -m simlan_data.export RUN --format coco|yolo|mot|aicity --out DIR``: a recording as a dataset.

The public name of ``python -m simlan_data.export``; the application is :mod:`simlan_data.apps.export`.
"""

from __future__ import annotations

from simlan_data.apps.export import cli, main

__all__ = ["cli", "main"]

if __name__ == "__main__":
    cli()
