"""Every docs page (and anchor) that the code, the tests and the benchmarks cite exists:
`docs/<page>.md` and `docs/<page>.md#<anchor>`, where an anchor is an explicit `{#id}` of a
heading or the id mkdocs gives a heading without one."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
CITE = re.compile(r"docs/([a-z0-9/_-]+\.md)(?:#([a-z0-9_-]+))?")
HEADING = re.compile(r"^#{1,6}\s+(.*?)\s*(?:\{#([a-z0-9_-]+)[^}]*\})?\s*$", re.M)


def anchors(page: Path) -> set[str]:
    """Explicit ids, and the slugs of headings without one (mkdocs' toc: lower case, words
    joined by '-', punctuation dropped)."""
    found = set()
    for title, explicit in HEADING.findall(page.read_text()):
        found.add(explicit or re.sub(r"[\s]+", "-", re.sub(r"[^\w\s-]", "", title).strip().lower()))
    return found


def citations() -> list[tuple[str, str, str | None]]:
    out = []
    for folder in ("swarm", "agents", "world", "tests", "benchmarks"):
        for path in sorted((ROOT / folder).rglob("*.py")):
            for page, anchor in CITE.findall(path.read_text()):
                out.append((str(path.relative_to(ROOT)), page, anchor or None))
    return out


def test_the_cited_docs_pages_and_anchors_exist():
    cited = citations()
    assert len(cited) > 30  # the pattern still finds them
    bad = []
    for where, page, anchor in cited:
        target = ROOT / "docs" / page
        if not target.is_file():
            bad.append(f"{where}: docs/{page} does not exist")
        elif anchor and anchor not in anchors(target):
            bad.append(f"{where}: docs/{page} has no #{anchor}")
    assert not bad, "\n".join(sorted(set(bad)))
