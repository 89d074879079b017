"""The documentation: the mkdocs site builds under --strict, the README stays short, relative links resolve.

House rule: README.md is at most 200 lines; everything else lives in the mkdocs-material site under
docs/ (mkdocs.yml at the repository root). mkdocs-material is in the ``test`` extra, so CI's
``pip install -e ".[test]"`` has it.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
README_MAX_LINES = 200

# [text](target) or ![alt](target); the target ends at whitespace or ')' (an optional "title" follows)
_LINK = re.compile(r"!?\[[^\]]*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
_FENCE = re.compile(r"^\s*(```|~~~)")


def _markdown_files() -> list[Path]:
    return [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]


def _links(path: Path) -> list[tuple[int, str]]:
    """(line number, target) of every Markdown link outside fenced code blocks and inline code."""
    out: list[tuple[int, str]] = []
    in_fence = False
    for no, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1):
        if _FENCE.match(line):
            in_fence = not in_fence
            continue
        if in_fence:
            continue
        text = re.sub(r"`[^`]*`", "", line)
        out.extend((no, m.group(1)) for m in _LINK.finditer(text))
    return out


def test_mkdocs_build_strict(tmp_path: Path) -> None:
    # no importorskip: mkdocs-material is in the test extra, and a missing one must fail, not skip
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    proc = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-d", str(tmp_path / "site")],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert proc.returncode == 0, f"mkdocs build --strict failed:\n{proc.stdout}\n{proc.stderr}"
    assert (tmp_path / "site" / "index.html").is_file()


def test_readme_is_short() -> None:
    lines = (ROOT / "README.md").read_text(encoding="utf-8").splitlines()
    assert len(lines) <= README_MAX_LINES, (
        f"README.md has {len(lines)} lines, at most {README_MAX_LINES}: move the details into a page under docs/"
    )


def test_every_docs_page_is_in_the_nav() -> None:
    nav = (ROOT / "mkdocs.yml").read_text(encoding="utf-8")
    missing = [
        p.name
        for p in sorted((ROOT / "docs").glob("*.md"))
        if not re.search(rf"\b{re.escape(p.name)}\b", nav)
    ]
    assert not missing, f"pages not listed in mkdocs.yml's nav: {missing}"


@pytest.mark.parametrize("md", _markdown_files(), ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_resolve(md: Path) -> None:
    broken = []
    for no, target in _links(md):
        if re.match(r"^[a-zA-Z][a-zA-Z0-9+.-]*:", target) or target.startswith(("#", "//")):
            continue  # http(s):, mailto:, ... and anchors within the page
        file_part = target.split("#", 1)[0].split("?", 1)[0]
        if not file_part:
            continue
        if not (md.parent / file_part).exists():
            broken.append(f"{md.relative_to(ROOT)}:{no}: {target}")
    assert not broken, "relative links to missing files:\n" + "\n".join(broken)
