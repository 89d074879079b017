"""What a recovery could not keep: time ranges per topic, where they are reported and how.

One :class:`Loss` per topic and damaged place (a chunk with a bad CRC or a bad record length, a
chunk cut short, unreadable bytes at the end, data the run never wrote)::

    salvage.scan --> Loss(topic, from, to, messages, cause)  (exact, from the chunk's message index,
                     or "*" = all topics with the chunk header's time range when nothing names them)
    recover      --> + the tail: what the RUNNING marker's clock reached beyond the file
                 --> printed (one line per range), INCOMPLETE (``losses``), the recovered bag's
                     custom_data ``simlan.recovered_losses`` (compact JSON) --> ``replay --info``
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from simlan_data.constants import INCOMPLETE_MARKER, NS_PER_S

ALL_TOPICS = "*"  # the lost messages' topics are unknown: every topic may have lost some
LOSSES_KEY = "simlan.recovered_losses"  # custom_data of a recovered bag
MAX_LISTED = 100  # ranges kept in INCOMPLETE and custom_data (the rest are counted)
MAX_MARKER_BYTES = 1 << 20


@dataclass(frozen=True)
class Loss:
    """Messages of one topic (or of all topics) in [from_ns, to_ns] that recovery could not keep."""

    topic: str
    from_ns: int
    to_ns: int | None  # None: until the run stopped, which nothing records
    messages: int | None  # None: how many is unknown
    cause: str

    def as_dict(self) -> dict[str, Any]:
        return {
            "topic": self.topic,
            "from_s": round(self.from_ns / NS_PER_S, 9),
            "to_s": None if self.to_ns is None else round(self.to_ns / NS_PER_S, 9),
            "messages": self.messages,
            "cause": self.cause,
        }


def describe(topic: str, from_s: float, to_s: float | None, messages: int | None) -> str:
    """``/clock 1.500-1.980 s (48 messages)``; ``all topics after 3.000 s (messages unknown)``."""
    name = "all topics" if topic == ALL_TOPICS else topic
    span = f"after {from_s:.3f} s" if to_s is None else f"{from_s:.3f}-{to_s:.3f} s"
    count = "messages unknown" if messages is None else f"{messages} message{'s' * (messages != 1)}"
    return f"{name} {span} ({count})"


def lost_s(losses: Iterable[Loss]) -> float:
    """Seconds of simulated time in the union of the ranges (open-ended ones excluded)."""
    spans = sorted((x.from_ns, x.to_ns) for x in losses if x.to_ns is not None)
    total, end = 0, None
    for a, b in spans:
        if end is None or a > end:
            total, end = total + (b - a), b
        elif b > end:
            total, end = total + (b - end), b
    return total / NS_PER_S


def totals(losses: list[Loss]) -> dict[str, Any]:
    """The summary's totals and the (capped) list."""
    return {
        "messages_lost": sum(x.messages or 0 for x in losses),
        "messages_lost_unknown": any(x.messages is None for x in losses),
        "lost_s": round(lost_s(losses), 9),
        "losses": [x.as_dict() for x in losses[:MAX_LISTED]],
        "losses_not_listed": max(0, len(losses) - MAX_LISTED),
    }


def encode(losses: list[Loss]) -> str:
    """Compact JSON for custom_data: ``[[topic, from_s, to_s, messages], ...]`` (capped)."""
    rows: list[list[Any]] = [
        [d["topic"], d["from_s"], d["to_s"], d["messages"]]
        for d in (x.as_dict() for x in losses[:MAX_LISTED])
    ]
    if len(losses) > MAX_LISTED:
        rows.append(["...", len(losses) - MAX_LISTED])
    return json.dumps(rows, separators=(",", ":"))


def _number(v: Any) -> float | None:
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else None


def _count(v: Any) -> int | None:
    return int(v) if isinstance(v, int) and not isinstance(v, bool) else None


class _NoAliasLoader(yaml.SafeLoader):
    """A marker is ours and has no aliases: one there is hostile (an alias bomb hangs PyYAML)."""

    def compose_node(self, parent: Any, index: Any) -> Any:
        if self.check_event(yaml.AliasEvent):
            raise yaml.YAMLError("YAML aliases are not accepted here")
        return super().compose_node(parent, index)


def decode(text: str) -> list[str]:
    """The lines ``encode`` stands for (what ``replay --info`` prints); tolerant of damage."""
    try:
        rows = json.loads(text)
    except (ValueError, RecursionError):
        return ["(unreadable)"]
    out = []
    for row in rows if isinstance(rows, list) else []:
        if isinstance(row, list) and len(row) == 2 and row[0] == "...":
            out.append(f"... and {row[1]} more ranges")
        elif isinstance(row, list) and len(row) == 4 and _number(row[1]) is not None:
            out.append(describe(str(row[0]), _number(row[1]) or 0.0, _number(row[2]), _count(row[3])))
    return out


def from_incomplete(run_dir: Path) -> list[str]:
    """The lines for the ``losses`` that ``run_dir/INCOMPLETE`` lists (none if it has none)."""
    path = run_dir / INCOMPLETE_MARKER
    try:
        if not path.is_file() or path.stat().st_size > MAX_MARKER_BYTES:
            return []
        data = yaml.load(path.read_text(), Loader=_NoAliasLoader)  # a SafeLoader without aliases
    except (OSError, yaml.YAMLError, UnicodeDecodeError, RecursionError):
        return []
    rows = data.get("losses") if isinstance(data, dict) else None
    out = []
    for d in rows if isinstance(rows, list) else []:
        if isinstance(d, dict) and _number(d.get("from_s")) is not None:
            topic, to_s, n = str(d.get("topic")), _number(d.get("to_s")), _count(d.get("messages"))
            out.append(describe(topic, _number(d["from_s"]) or 0.0, to_s, n))
    return out
