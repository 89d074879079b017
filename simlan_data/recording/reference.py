"""The topic table of the recording format (docs/recording.md), generated from the schema module.

One row per topic pattern: the global topics (``schema.GLOBAL_TOPICS``), the topics of a camera
(``schema.camera_topics``, ``<id>``) and of an agent (``schema.agent_topics``, ``<ns>``). A camera
topic whose name or type depends on an encoding gets one row per variant, with the setting that
selects it. ``python -m simlan_data.apps.reference`` puts the table into docs/recording.md.
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass

from simlan_data.recording import schema

CAMERA_ID = "<id>"
NAMESPACE = "<ns>"


@dataclass(frozen=True)
class TopicRow:
    """A row of the table: a topic pattern, its type, what it holds and when it is recorded."""

    name: str
    msgtype: str
    description: str
    when: str


def camera_rows(encodings: dict[str, tuple[str, ...]]) -> list[TopicRow]:
    """Rows of one camera's topics for every encoding of each stream.

    ``encodings`` maps each keyword parameter of ``schema.camera_topics`` (a stream) to its
    encodings, the default first (``recording.<stream>_encoding``). A topic that another encoding
    of its stream replaces names the setting that records it.
    """
    params = [
        p.name
        for p in inspect.signature(schema.camera_topics).parameters.values()
        if p.kind is inspect.Parameter.KEYWORD_ONLY
    ]
    defaults = {p: encodings[p][0] for p in params}

    def topics(**change: str) -> list[schema.Topic]:
        return list(schema.camera_topics(CAMERA_ID, **{**defaults, **change}).values())

    def keys(**change: str) -> set[tuple[str, str]]:
        return {(t.name, t.msgtype) for t in topics(**change)}

    out: list[TopicRow] = []
    seen: set[tuple[str, str]] = set()
    for topic in topics():
        key = (topic.name, topic.msgtype)
        stream = next((p for p in params if any(key not in keys(**{p: e}) for e in encodings[p][1:])), "")
        when = f"`recording.{stream}_encoding={defaults[stream]}`" if stream else ""
        out.append(TopicRow(topic.name, topic.msgtype, topic.description, when))
        seen.add(key)
    for param in params:
        for encoding in encodings[param][1:]:
            for topic in topics(**{param: encoding}):
                if (topic.name, topic.msgtype) not in seen:
                    seen.add((topic.name, topic.msgtype))
                    when = f"`recording.{param}_encoding={encoding}`"
                    out.append(TopicRow(topic.name, topic.msgtype, topic.description, when))
    return out


def rows(encodings: dict[str, tuple[str, ...]]) -> list[TopicRow]:
    """Every row: global topics, a camera's, an agent's."""
    out = [TopicRow(t.name, t.msgtype, t.description, "") for t in schema.GLOBAL_TOPICS]
    out += camera_rows(encodings)
    out += [
        TopicRow(t.name, t.msgtype, t.description, "`cameras.streams` with `instance`")
        for t in schema.instance_topics(CAMERA_ID).values()
    ]
    out += [TopicRow(t.name, t.msgtype, t.description, "") for t in schema.agent_topics(NAMESPACE).values()]
    return out
