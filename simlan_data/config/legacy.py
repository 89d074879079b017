"""Recorded configs from before the ``algorithms`` section, read as if they had one.

Until the plug-in seam each built-in algorithm kept its keys in a section of its own (and people
detection inside ``safety``). A replay of such a recording runs the built-ins with those keys; this
module is the one place that knows where they were.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from simlan_data.algorithms.registry import DEFAULTS, NAME_KEY


def _localizer(config: Mapping[str, Any]) -> dict[str, Any] | None:
    return {k: v for k, v in (config.get("localization") or {}).items() if k != "source"}


def _safety(config: Mapping[str, Any]) -> dict[str, Any] | None:
    if "safety" not in config:
        return None  # (no section: the built-in with its defaults)
    return {k: v for k, v in (config.get("safety") or {}).items() if k != "people"}


def _stitcher(config: Mapping[str, Any]) -> dict[str, Any] | None:
    return {k: v for k, v in (config.get("birdseye") or {}).items() if k == "feather_m"}


def _posemap(config: Mapping[str, Any]) -> dict[str, Any] | None:
    # the old section's refine keys were training's: the drive applied the model's saved fit
    return {"model": (config.get("posemap") or {}).get("drive_model") or ""}


# role -> the built-in's keys in a recording made before the algorithms section
LEGACY: dict[str, Callable[[Mapping[str, Any]], dict[str, Any] | None]] = {
    "localizer": _localizer,
    "safety": _safety,
    "stitcher": _stitcher,
    "posemap": _posemap,
}


def with_algorithms(config: Mapping[str, Any]) -> dict[str, Any]:
    """``config`` (a recording's /simlan/config) with ``algorithms.ROLE`` for every role it lacks
    that an older recording kept elsewhere: the built-in, with its keys from the old place;
    ``people`` from ``safety.people``. A current recording comes back as it is (a copy)."""
    out = dict(config)
    algorithms = dict(out.get("algorithms") or {})
    for role, old_keys in LEGACY.items():
        if algorithms.get(role):
            continue
        values = old_keys(config)
        if values is not None:
            algorithms[role] = {NAME_KEY: DEFAULTS[role], **values}
    out["algorithms"] = algorithms
    if out.get("people") is None and "people" in (config.get("safety") or {}):
        out["people"] = config["safety"]["people"]
    return out
