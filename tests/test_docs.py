"""The documentation belongs to the project: a user who installs metriplex can read everything
that its code, tests, benchmarks and docs refer to.

- No file under src/, tests/, benchmarks/ or docs/, nor README.md, refers to design or physics
  notes kept outside the repository; the project's own are docs/design.md and docs/physics.md.
- Every relative link of README.md and docs/*.md (Markdown links, images, HTML ``src``/``href``)
  points to a file of the repository, and an ``#anchor`` into a Markdown file to one of its
  headings.
- A citation of a section in prose or in a docstring, written as the document's path, a comma
  and the heading in single quotes, names a heading that exists.
"""

from __future__ import annotations

import re
from pathlib import Path
from urllib.parse import unquote

import pytest

ROOT = Path(__file__).resolve().parents[1]
SCANNED = ("src", "tests", "benchmarks", "docs")
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]

# Built from pieces, so that this file does not contain the strings it looks for.
FORBIDDEN = tuple(f"{name}.md" for name in ("DESIGN", "PHYSICS", "STYLE")) + (
    "../" + "shared",
    "/work/" + "shared",
)


def _skipped(path: Path) -> bool:
    parts = path.relative_to(ROOT).parts
    return any(p == "__pycache__" or p.startswith(".") or p.endswith(".egg-info") for p in parts)


def _text_files() -> list[Path]:
    files = [ROOT / "README.md"]
    for top in SCANNED:
        files += [p for p in sorted((ROOT / top).rglob("*")) if p.is_file() and not _skipped(p)]
    return files


def _text(path: Path) -> str | None:
    data = path.read_bytes()
    if b"\0" in data:  # binary (figures, data files)
        return None
    return data.decode("utf-8", errors="replace")


def test_no_reference_to_notes_outside_the_project():
    found = []
    for path in _text_files():
        text = _text(path)
        if text is None:
            continue
        for lineno, line in enumerate(text.splitlines(), 1):
            for bad in FORBIDDEN:
                if bad in line:
                    found.append(f"{path.relative_to(ROOT)}:{lineno}: {bad!r}")
    assert not found, (
        "these lines refer to files outside the project, which users cannot read; cite "
        "docs/design.md or docs/physics.md (with the section) instead:\n" + "\n".join(found)
    )


# -- Markdown ---------------------------------------------------------------------------------

def _without_code(text: str) -> list[str]:
    """The lines of a Markdown text, with fenced code blocks blanked and inline code removed
    (links inside code are not links, and a ``#`` line in a code block is not a heading)."""
    lines, fence = [], None
    for line in text.splitlines():
        m = re.match(r"^\s{0,3}(`{3,}|~{3,})", line)
        if fence is None and m:
            fence = m.group(1)[0] * 3
            lines.append("")
            continue
        if fence is not None:
            if line.strip().startswith(fence):
                fence = None
            lines.append("")
            continue
        lines.append(re.sub(r"(`+)(?:(?!\1).)+\1", "", line))
    return lines


def _heading_texts(path: Path) -> list[str]:
    texts = []
    for line in _without_code(path.read_text(encoding="utf-8")):
        m = re.match(r"^\s{0,3}#{1,6}\s+(.*?)\s*#*\s*$", line)
        if m:
            text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", m.group(1))  # links: their text
            texts.append(re.sub(r"[*_`]", "", text).strip())
    return texts


def _headings_with_code(path: Path) -> list[str]:
    """Heading texts with inline code kept (as rendered), for GitHub's anchors."""
    texts, fence = [], None
    for line in path.read_text(encoding="utf-8").splitlines():
        m = re.match(r"^\s{0,3}(`{3,}|~{3,})", line)
        if fence is None and m:
            fence = m.group(1)[0] * 3
            continue
        if fence is not None:
            if line.strip().startswith(fence):
                fence = None
            continue
        m = re.match(r"^\s{0,3}#{1,6}\s+(.*?)\s*#*\s*$", line)
        if m:
            texts.append(re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", m.group(1)))
    return texts


def _anchors(path: Path) -> set[str]:
    """GitHub's heading anchors: lower case, punctuation dropped, spaces to hyphens, ``-1``,
    ``-2``, ... for repeated headings."""
    seen: dict[str, int] = {}
    anchors = set()
    for text in _headings_with_code(path):
        slug = re.sub(r"[^\w\- ]", "", text.strip().lower()).replace(" ", "-")
        k = seen.get(slug, 0)
        seen[slug] = k + 1
        anchors.add(slug if k == 0 else f"{slug}-{k}")
    return anchors


LINK = re.compile(r"!?\[[^\]]*\]\(\s*<?([^)\s>]*)>?(?:\s+(?:\"[^\"]*\"|'[^']*'))?\s*\)")
HTML = re.compile(r"""\b(?:src|href)\s*=\s*["']([^"']+)["']""")
DEFINITION = re.compile(r"^\s{0,3}\[[^\]]+\]:\s*<?([^\s>]+)>?")


def _links(path: Path) -> list[tuple[int, str]]:
    out = []
    for lineno, line in enumerate(_without_code(path.read_text(encoding="utf-8")), 1):
        for pattern in (LINK, HTML, DEFINITION):
            out += [(lineno, m.group(1)) for m in pattern.finditer(line)]
    return out


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_point_into_the_repository(doc):
    broken = []
    for lineno, target in _links(doc):
        if not target or re.match(r"^[A-Za-z][A-Za-z0-9+.-]*:", target):  # http:, mailto:, ...
            continue
        file_part, _, anchor = target.partition("#")
        where = f"{doc.relative_to(ROOT)}:{lineno}: {target!r}"
        dest = (doc.parent / unquote(file_part)).resolve() if file_part else doc
        try:
            dest.relative_to(ROOT)
        except ValueError:
            broken.append(f"{where} leaves the repository")
            continue
        if not dest.exists():
            broken.append(f"{where}: no such file")
        elif anchor and dest.suffix == ".md" and unquote(anchor) not in _anchors(dest):
            broken.append(f"{where}: {dest.name} has no heading with this anchor")
    assert not broken, "broken links:\n" + "\n".join(broken)


CITATION = re.compile(r"docs/(design|physics)\.md,\s+'([^']+)'")


def test_cited_sections_exist():
    headings = {name: set(_heading_texts(ROOT / "docs" / f"{name}.md"))
                for name in ("design", "physics")}
    missing = []
    for path in _text_files():
        text = _text(path)
        if text is None:
            continue
        for m in CITATION.finditer(text):
            # A citation may wrap onto a comment or docstring continuation line.
            section = " ".join(re.sub(r"\n\s*#?", " ", m.group(2)).split())
            if section not in headings[m.group(1)]:
                lineno = text.count("\n", 0, m.start()) + 1
                missing.append(f"{path.relative_to(ROOT)}:{lineno}: docs/{m.group(1)}.md has "
                               f"no section {section!r}")
    assert not missing, "\n".join(missing)


def test_readme_links_the_design_and_physics_documents():
    targets = {target for _, target in _links(ROOT / "README.md")}
    assert {"docs/design.md", "docs/physics.md"} <= targets
