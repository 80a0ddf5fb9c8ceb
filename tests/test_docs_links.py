"""Every relative link in the README and docs/ reaches a file, and its #anchor a heading of it
(GitHub's anchors: lower case, punctuation dropped, spaces to hyphens, -1, -2 for repeats)."""

import re
from collections import Counter
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]


def anchors(markdown: str) -> set[str]:
    """The anchors GitHub gives the headings of ``markdown`` (fenced code left out)."""
    seen, out, fenced = Counter(), set(), False
    for line in markdown.splitlines():
        if line.startswith("```"):
            fenced = not fenced
        elif not fenced and (m := re.match(r"#{1,6} (.*)", line)):
            slug = re.sub(r"[^\w\- ]", "", m.group(1).strip().lower()).replace(" ", "-")
            out.add(slug if not seen[slug] else f"{slug}-{seen[slug]}")
            seen[slug] += 1
    return out


def test_anchors_follow_github():
    text = "# Why `--fast` breaks ACES (2026)\n```\n# not a heading\n```\n## A\n## A\n"
    assert anchors(text) == {"why---fast-breaks-aces-2026", "a", "a-1"}


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_resolve(doc):
    broken = []
    for url in re.findall(r"\]\(([^)\s]+)\)", doc.read_text()):
        if re.match(r"[a-z]+:", url):
            continue  # http(s), mailto: not checked offline
        path, _, anchor = url.partition("#")
        target = (doc.parent / path).resolve() if path else doc
        if not target.exists():
            broken.append(f"{url}: no such file")
        elif anchor and target.suffix == ".md" and anchor not in anchors(target.read_text()):
            broken.append(f"{url}: no such heading")
    assert not broken, f"{doc.name}: " + "; ".join(broken)
