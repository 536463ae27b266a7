"""Every relative link in the user docs (README.md, docs/**/*.md) reaches a file that exists, and a link
to a heading (``docs/replay.md#real-imu-flights-ansfl``, ``#message-signing``) reaches a heading of that
file, by GitHub's anchor rule. The docs stay user docs: no design-doc section signs, no paths into the
project's shared data or the machine it was developed on. Pure text, milliseconds."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
FENCE = re.compile(r"^ *```.*?^ *```", re.S | re.M)


def prose(text: str) -> str:
    """``text`` without fenced blocks and code spans (a link inside either is not a link)."""
    text = FENCE.sub(lambda m: "\n" * m.group(0).count("\n"), text)
    return re.sub(r"`[^`\n]*`", "", text)


def anchors(doc: Path) -> set[str]:
    """GitHub's heading anchors: lower case, punctuation dropped, spaces to hyphens, ``-1``, ``-2`` for
    repeats; and explicit ``<a name=…>``/``id=…``."""
    text = FENCE.sub("", doc.read_text(encoding="utf-8"))
    out: set[str] = set()
    seen: dict[str, int] = {}
    for heading in re.findall(r"^#{1,6}[ \t]+(.+?)[ \t#]*$", text, re.M):
        slug = re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")
        n = seen.get(slug, 0)
        seen[slug] = n + 1
        out.add(slug if n == 0 else f"{slug}-{n}")
    out.update(re.findall(r"<a\s+(?:name|id)=\"([^\"]+)\"", text))
    return out


def links(doc: Path) -> list[tuple[int, str]]:
    """(line, target) of every inline link or image and every reference definition."""
    text = prose(doc.read_text(encoding="utf-8"))
    out = []
    inline = r"\]\(\s*<?([^)>\s]+)>?(?:\s+\"[^\"]*\")?\s*\)"
    for m in re.finditer(rf"{inline}|^ {{0,3}}\[[^\]]+\]:\s*(\S+)", text, re.M):
        out.append((text[: m.start()].count("\n") + 1, m.group(1) or m.group(2)))
    return out


def broken(doc: Path) -> list[str]:
    problems = []
    for line, target in links(doc):
        if re.match(r"[a-z][a-z0-9+.-]*:", target):  # https:, mailto:
            continue
        path, _, anchor = target.partition("#")
        dest = (doc.parent / path).resolve() if path else doc
        where = f"{doc.relative_to(ROOT) if doc.is_relative_to(ROOT) else doc.name}:{line}"
        if not dest.exists():
            problems.append(f"{where}: no file {target}")
        elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
            problems.append(f"{where}: no heading #{anchor} in {path or 'this file'}")
    return problems


def test_every_relative_link_and_anchor_resolves() -> None:
    assert sum(len(links(doc)) for doc in DOCS) > 200  # the collector finds the docs' links
    problems = [p for doc in DOCS for p in broken(doc)]
    assert not problems, "\n".join(problems)


@pytest.mark.parametrize("link", ["[x](nowhere.md)", "[x](other.md#no-such-heading)", "[x](#no-such-heading)",
                                  "[x]: nowhere.md"])
def test_the_check_finds_a_broken_link(tmp_path: Path, link: str) -> None:
    (tmp_path / "other.md").write_text("# Other\n\n## A heading, with `code` (and more)\n", encoding="utf-8")
    doc = tmp_path / "doc.md"
    doc.write_text(f"# Doc\n\n[fine](other.md#a-heading-with-code-and-more)\n{link}\n", encoding="utf-8")
    assert len(broken(doc)) == 1
    doc.write_text("# Doc\n\n[fine](other.md#a-heading-with-code-and-more), [here](#doc), `[code](no.md)`\n",
                   encoding="utf-8")
    assert broken(doc) == []


def test_user_docs_name_no_design_sections_or_development_paths() -> None:
    bad = []
    for doc in DOCS:
        for n, line in enumerate(doc.read_text(encoding="utf-8").splitlines(), 1):
            if re.search(r"§|\.\./shared|(?<![\w.])shared/data|/work/", line):
                bad.append(f"{doc.relative_to(ROOT)}:{n}: {line.strip()[:100]}")
    assert not bad, "\n".join(bad)
