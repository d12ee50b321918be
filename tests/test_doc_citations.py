"""Every citation of the project's docs names a doc that exists and, when it quotes a section, one the doc has.

Code, configs and docs cite ``docs/NAME.md`` and often a section in quotes right after it (``docs/model.md,
"Rendering on a CPU"``); a section counts when a heading of that doc, or a paragraph's bold lead (``**Report
inputs.**``), starts with the quoted words. A renamed or removed section then fails here instead of leaving the
reader at a dead reference.
"""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
SOURCES = ("stages", "workflow", "benchmarks", "scripts", "config", "docs", "tests")
TOP_FILES = ("README.md", "Snakefile", "Makefile", "pyproject.toml")
SUFFIXES = {".py", ".smk", ".yaml", ".yml", ".md", ".sh", ".toml", ".html", ".j2"}

# docs/NAME.md, then optionally a quoted section after a comma/colon/space, across a line break and its comment mark
CITATION = re.compile(
    r"docs/([\w.-]+\.md)"
    r"(?:[,:]?[ \t]*(?:\n[ \t]*(?:#|//)?[ \t]*)?(?:section[ \t]+)?[\"“]([^\"”\n]+)[\"”])?"
)


def _sections(doc: Path) -> list[str]:
    text = doc.read_text()
    heads = [re.sub(r"^#+\s*", "", line).strip() for line in text.splitlines() if line.startswith("#")]
    leads = re.findall(r"^\*\*([^*]+)\*\*", text, re.M)  # a paragraph's bold lead
    leads += re.findall(r"(?<=[.:] )\*\*([^*]+)\*\*", text)  # ... or one that opens a sentence within it
    return [s.replace("`", "") for s in heads + [lead.strip() for lead in leads]]


def _citations() -> list[tuple[str, int, str, str | None]]:
    files = [ROOT / name for name in TOP_FILES if (ROOT / name).is_file()]
    for top in SOURCES:
        files += [p for p in (ROOT / top).rglob("*") if p.suffix in SUFFIXES and p.is_file()]
    out = []
    for path in sorted(files):
        if path == Path(__file__).resolve():
            continue
        text = path.read_text(errors="replace")
        for m in CITATION.finditer(text):
            line = text.count("\n", 0, m.start()) + 1
            out.append((str(path.relative_to(ROOT)), line, m.group(1), m.group(2)))
    return out


def test_every_cited_doc_and_section_exists():
    sections = {doc.name: _sections(doc) for doc in DOCS.glob("*.md")}
    citations = _citations()
    assert len(citations) > 100, "the citation pattern found almost nothing: is it still the project's form?"
    dead = []
    for where, line, doc, section in citations:
        if doc not in sections:
            dead.append(f"{where}:{line}: docs/{doc} does not exist")
        elif section and not any(s.startswith(section.replace("`", "").rstrip(".")) for s in sections[doc]):
            dead.append(f'{where}:{line}: docs/{doc} has no section "{section}"')
    assert not dead, "dead doc references:\n" + "\n".join(dead)
