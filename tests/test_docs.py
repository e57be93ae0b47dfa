"""The README renders as written, and the user guide builds.

README.md is parsed with a CommonMark parser (markdown-it-py), the way GitHub reads it: every code fence is closed
by a bare fence line and names its language, every line that looks like a heading is a heading (not text swallowed
by a runaway fence), and every relative link and image resolves to a file of the repository. The guide (docs/,
mkdocs.yml) is built with ``mkdocs build --strict``, which fails on a broken link, anchor or image.
"""

from __future__ import annotations

import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
MAX_README_BYTES = 12 * 1024
"""The README is the front door; everything longer belongs in docs/."""

CLOSING_FENCE = re.compile(r"^ {0,3}(`{3,}|~{3,})[ \t]*$")
HEADING_LINE = re.compile(r"^#{1,6}(?:[ \t]|$)")
EXTERNAL = re.compile(r"^[a-zA-Z][a-zA-Z0-9+.-]*:")  # http:, https:, mailto:, ...


def markdown_problems(text: str, base: Path) -> list[str]:
    """What would make ``text`` (a Markdown file in ``base``) render other than written, one line per problem.

    - a fence without a language, or not closed by a bare fence line of its own kind (a fence with text after it
      does not close, and the fence runs on);
    - an indented code block (in these files only a fence gone out of step makes one);
    - a line that looks like a heading but is not one; inside a fence a ``# `` line is a shell or Python comment,
      a ``## `` line never is;
    - a relative link or image whose file does not exist.
    """
    from markdown_it import MarkdownIt

    tokens = MarkdownIt("commonmark").enable("table").parse(text)
    lines = text.splitlines()
    problems: list[str] = []
    in_fence: set[int] = set()
    for tok in tokens:
        if tok.type == "fence":
            start, end = tok.map
            in_fence.update(range(start, end))
            last = lines[end - 1] if end - 1 < len(lines) else ""
            closed = end - start >= 2 and CLOSING_FENCE.match(last)
            if not closed or last.strip()[0] != tok.markup[0] or len(last.strip()) < len(tok.markup):
                problems.append(f"line {start + 1}: the fence opened here is not closed by a bare {tok.markup} line")
            if not tok.info.strip():
                problems.append(f"line {start + 1}: a fence without a language (write ```text for plain text)")
        elif tok.type == "code_block":
            problems.append(f"line {tok.map[0] + 1}: an indented code block (a fence out of step?)")
    headings = {tok.map[0] for tok in tokens if tok.type == "heading_open"}
    for i, line in enumerate(lines):
        if HEADING_LINE.match(line) and i not in headings and not (i in in_fence and line.startswith("# ")):
            problems.append(f"line {i + 1}: {line.strip()!r} is not rendered as a heading")
    for tok in tokens:
        for child in tok.children or []:
            target = child.attrs.get("href") if child.type == "link_open" else child.attrs.get("src")
            if child.type not in ("link_open", "image") or not target:
                continue
            path = str(target).split("#", 1)[0]
            if EXTERNAL.match(str(target)) or not path:
                continue
            if not (base / path).exists():
                problems.append(f"line {tok.map[0] + 1}: {child.type.replace('_open', '')} to {target}: no such file")
    return problems


def test_the_readme_renders_as_written():
    pytest.importorskip("markdown_it", reason="markdown-it-py is in the dev extra (make installs it)")
    assert markdown_problems(README.read_text(), ROOT) == []


def test_the_readme_is_a_front_door():
    size = len(README.read_bytes())
    assert size <= MAX_README_BYTES, f"README.md is {size} bytes; move detail to docs/ (at most {MAX_README_BYTES})"


@pytest.mark.parametrize("page", sorted((ROOT / "docs").glob("*.md")), ids=lambda p: p.name)
def test_every_guide_page_renders_as_written(page):
    pytest.importorskip("markdown_it", reason="markdown-it-py is in the dev extra (make installs it)")
    assert markdown_problems(page.read_text(), page.parent) == []


def test_the_checker_finds_what_breaks_a_page(tmp_path):
    """A fence with text after it runs on and swallows a heading; a bare fence later opens a block that never
    closes; a link to a missing file; each is named."""
    pytest.importorskip("markdown_it", reason="markdown-it-py is in the dev extra (make installs it)")
    (tmp_path / "there.md").write_text("x\n")
    broken = "\n".join(
        [
            "# Title",
            "",
            "```python",
            "x = 1",
            "``` and then some text",
            "",
            "## Architecture",
            "",
            "```",
            "",
            "    indented",
            "",
            "[here](there.md) and [gone](docs/missing.md) and ![pic](missing.png) and [web](https://example.org)",
            "",
            "```",
            "never closed",
        ]
    )
    problems = "\n".join(markdown_problems(broken, tmp_path))
    assert "'## Architecture' is not rendered as a heading" in problems
    assert "line 15: the fence opened here is not closed" in problems
    assert "line 15: a fence without a language" in problems
    assert "line 11: an indented code block" in problems
    assert "docs/missing.md: no such file" in problems and "missing.png: no such file" in problems
    assert "there.md" not in problems and "example.org" not in problems
    fixed = "# Title\n\n```python\nx = 1\n```\n\n## Architecture\n\n[here](there.md)\n"
    assert markdown_problems(fixed, tmp_path) == []


def test_the_guide_builds_strictly(tmp_path):
    if importlib.util.find_spec("mkdocs") is None or importlib.util.find_spec("material") is None:
        pytest.skip("mkdocs and mkdocs-material are the 'docs' extra (make installs it)")
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1")
    cmd = [sys.executable, "-m", "mkdocs", "build", "--strict", "--config-file", str(ROOT / "mkdocs.yml")]
    done = subprocess.run([*cmd, "--site-dir", str(tmp_path / "site")], capture_output=True, text=True, env=env)
    assert done.returncode == 0, done.stderr[-3000:]
    assert (tmp_path / "site" / "index.html").exists()


def test_the_version_is_one_in_pyproject_citation_and_changelog():
    import yaml

    version = re.search(r'^version = "([^"]+)"', (ROOT / "pyproject.toml").read_text(), re.MULTILINE).group(1)
    citation = yaml.safe_load((ROOT / "CITATION.cff").read_text())
    assert str(citation["version"]) == version
    assert f"## [{version}] - " in (ROOT / "CHANGELOG.md").read_text()
    import quad_uneven_env

    assert quad_uneven_env.__version__ == version
    paper = citation["references"][0]["title"]
    assert paper in README.read_text(), "the README cites the paper CITATION.cff references, by the same title"
    assert "MIT" in (ROOT / "LICENSE").read_text().splitlines()[0] and citation["license"] == "MIT"
