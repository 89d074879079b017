"""Regenerate the reference parts of the docs: the config keys and the recording's topic table.

    python -m simlan_data.apps.reference            # rewrite them in docs/
    python -m simlan_data.apps.reference --check    # exit 1 (and say which) when one is stale

Each page keeps its hand-written prose; the generated part sits between two marker comments::

    <!-- BEGIN GENERATED config-reference: python -m simlan_data.apps.reference -->
    ...
    <!-- END GENERATED config-reference -->

Sources: the config dataclasses (:mod:`simlan_data.config.reference`, composed with ``conf/``
for the defaults) and the recording schema (:mod:`simlan_data.recording.reference`).
"""

from __future__ import annotations

import argparse
import inspect
import re
import sys
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from simlan_data.errors import EXIT_BAD_INPUT

DOCS = Path(__file__).resolve().parents[2] / "docs"
COMMAND = "python -m simlan_data.apps.reference"


@dataclass(frozen=True)
class Generated:
    """A generated part of a docs page."""

    name: str
    page: Path
    render: Callable[[], str]


def cell(text: str) -> str:
    """Text for a Markdown table cell: pipes escaped, ``<`` outside code spans escaped (so
    ``<ns>`` is not taken for an HTML tag), one line."""
    parts = re.split(r"(`[^`]*`)", text.replace("\n", " "))
    return "".join(p if p.startswith("`") else p.replace("<", "&lt;") for p in parts).replace("|", "\\|")


def config_markdown() -> str:
    """Every config key: one table per section."""
    from simlan_data.config.reference import sections

    out = []
    for sec in sections():
        out.append(f"### {sec.title}\n")
        if sec.doc:
            out.append(f"{cell(sec.doc)}\n")
        out.append("| key | type | default | allowed | what |\n| --- | --- | --- | --- | --- |")
        out += [
            f"| `{r.key}` | {cell(r.type)} | {cell(r.default)} | {cell(r.allowed)} | {cell(r.doc)} |"
            for r in sec.rows
        ]
        out.append("")
    return "\n".join(out)


def topics_markdown() -> str:
    """The recording's topic table."""
    from simlan_data.config import schema as config_schema
    from simlan_data.recording import reference, schema

    defaults = config_schema.RecordingConfig()
    encodings = {}
    for param in inspect.signature(schema.camera_topics).parameters.values():
        if param.kind is inspect.Parameter.KEYWORD_ONLY:
            default = getattr(defaults, f"{param.name}_encoding")
            choices = getattr(config_schema, f"{param.name.upper()}_ENCODINGS", (default,))
            encodings[param.name] = (default, *(c for c in choices if c != default))
    lines = ["| topic | type | content | encoding setting |", "| --- | --- | --- | --- |"]
    lines += [
        f"| `{r.name}` | {r.msgtype} | {cell(r.description)} | {cell(r.when)} |"
        for r in reference.rows(encodings)
    ]
    return "\n".join(lines) + "\n"


PARTS = (
    Generated("config-reference", DOCS / "configuration.md", config_markdown),
    Generated("topic-table", DOCS / "recording.md", topics_markdown),
)


def begin_marker(name: str) -> str:
    return f"<!-- BEGIN GENERATED {name}: {COMMAND} -->"


def end_marker(name: str) -> str:
    return f"<!-- END GENERATED {name} -->"


def splice(text: str, name: str, body: str) -> str:
    """``text`` with the part between ``name``'s markers replaced by ``body``.

    Raises:
        ValueError: the page lacks the markers (each must appear once, BEGIN before END).
    """
    begin, end = begin_marker(name), end_marker(name)
    if text.count(begin) != 1 or text.count(end) != 1 or text.index(begin) > text.index(end):
        raise ValueError(f"expected one '{begin}' line followed by one '{end}' line")
    head, rest = text.split(begin, 1)
    _, tail = rest.split(end, 1)
    return f"{head}{begin}\n\n{body.strip()}\n\n{end}{tail}"


def stale(parts: Sequence[Generated] = PARTS) -> list[Generated]:
    """The parts whose page differs from what the sources generate now."""
    out = []
    for part in parts:
        text = part.page.read_text(encoding="utf-8")
        if splice(text, part.name, part.render()) != text:
            out.append(part)
    return out


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog=COMMAND, description=__doc__.split("\n", 1)[0])
    parser.add_argument("--check", action="store_true", help="exit 1 if a generated part is out of date")
    args = parser.parse_args(argv)
    try:
        if args.check:
            old = stale()
            for part in old:
                print(f"{part.page.relative_to(DOCS.parent)}: {part.name} is out of date; run {COMMAND}")
            return 1 if old else 0
        for part in PARTS:
            text = part.page.read_text(encoding="utf-8")
            new = splice(text, part.name, part.render())
            if new != text:
                part.page.write_text(new, encoding="utf-8")
                print(f"wrote {part.page.relative_to(DOCS.parent)} ({part.name})")
    except ValueError as err:
        print(
            f"error: markers missing in {part.page}: {err}; add them around the generated part",
            file=sys.stderr,
        )
        return EXIT_BAD_INPUT
    return 0


if __name__ == "__main__":
    sys.exit(main())
