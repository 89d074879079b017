"""The generated reference parts of the docs: config keys (docs/configuration.md) and the
recording's topic table (docs/recording.md) match the dataclasses and the schema module.

When a test here fails after a config field or a topic changed, regenerate the pages with
``python -m simlan_data.apps.reference`` and commit them.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from simlan_data.apps import reference
from simlan_data.config.reference import sections as config_sections
from simlan_data.config.validation import _typed_keys
from simlan_data.recording import schema

ROOT = Path(__file__).resolve().parents[1]


def _generated(page: Path, name: str) -> str:
    text = page.read_text(encoding="utf-8")
    return text.split(reference.begin_marker(name), 1)[1].split(reference.end_marker(name), 1)[0]


def test_committed_pages_are_up_to_date() -> None:
    stale = [f"{p.page.relative_to(ROOT)} ({p.name})" for p in reference.stale()]
    assert not stale, f"out of date: {', '.join(stale)}; run {reference.COMMAND} and commit the pages"


def test_every_config_key_is_in_the_reference() -> None:
    page = _generated(ROOT / "docs" / "configuration.md", "config-reference")
    documented = set(re.findall(r"^(?:\| |### )`([^`]+)`", page, flags=re.MULTILINE))  # keys, sections
    # every dotted key of the schema (validation's own walk), and each algorithm's keys
    missing = [k for k in _typed_keys() if k not in documented and k.split(".")[0] != "algorithms"]
    assert not missing, f"keys missing from docs/configuration.md: {missing}"
    for role in ("localizer", "safety", "stitcher", "coordinator", "posemap"):
        assert any(k.startswith(f"algorithms.{role}.") for k in documented), role
    assert "`algorithms.safety.ttc.stop_cpa_m`" in page  # a nested section of an algorithm


def test_reference_rows_carry_default_allowed_values_and_comment() -> None:
    rows = {r.key: r for sec in config_sections() for r in sec.rows}
    quality = rows["recording.jpeg_quality"]
    assert (quality.type, quality.default, quality.allowed) == ("int", "`85`", "must be within 1..100")
    assert rows["world.fidelity"].allowed == "expected one of empty, light, medium, default"
    assert rows["recording.fsync"].doc.startswith("also force each flush to the disk")  # the field's comment
    assert rows["cameras.ids"].default.startswith("`[160, 161")  # the composed default, not MISSING
    assert rows["world.physics.<name>.restitution"].allowed == "must be in [0, 1]"
    # a key whose check names another key gets nothing from it
    assert "unobserved" not in rows["algorithms.localizer.unobserved_timeout_s"].allowed


def test_every_topic_of_the_schema_is_in_the_table() -> None:
    page = _generated(ROOT / "docs" / "recording.md", "topic-table")
    documented = set(re.findall(r"^\| `([^`]+)` \| ([\w/]+) \|", page, flags=re.MULTILINE))
    expected = {(t.name, t.msgtype) for t in schema.GLOBAL_TOPICS}
    expected |= {(t.name, t.msgtype) for t in schema.agent_topics("<ns>").values()}
    for rgb, depth, semantic in [("jpeg", "png", "png"), ("raw", "raw", "raw")]:
        topics = schema.camera_topics("<id>", rgb=rgb, depth=depth, semantic=semantic).values()
        expected |= {(t.name, t.msgtype) for t in topics}
    assert expected <= documented, f"missing: {sorted(expected - documented)}"


def test_a_stale_page_is_found_and_rewritten(tmp_path: Path) -> None:
    page = tmp_path / "page.md"
    begin, end = reference.begin_marker("part"), reference.end_marker("part")
    page.write_text(f"# Title\n\nprose\n\n{begin}\n\nold table\n\n{end}\n\nmore prose\n", encoding="utf-8")
    part = reference.Generated("part", page, lambda: "| new |\n")
    assert reference.stale([part]) == [part]
    page.write_text(
        reference.splice(page.read_text(encoding="utf-8"), "part", part.render()), encoding="utf-8"
    )
    assert reference.stale([part]) == []
    text = page.read_text(encoding="utf-8")
    assert "prose\n" in text and "more prose\n" in text and "old table" not in text


def test_a_page_without_markers_is_refused() -> None:
    with pytest.raises(ValueError, match="BEGIN GENERATED part"):
        reference.splice("# no markers\n", "part", "x")


def test_cells_escape_pipes_and_tags_outside_code() -> None:
    assert reference.cell("a | b `<ns>` <ns>") == "a \\| b `<ns>` &lt;ns>"
