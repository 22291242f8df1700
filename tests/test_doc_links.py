"""The documentation's references resolve: links, file paths, and the RESULTS.md sections that text cites.

Three kinds of reference, each checked against the repository as it is:

- every relative Markdown link or image of README.md and docs/*.md points to an existing file, and its
  ``#anchor`` to a heading of that file (GitHub's slugs);
- every repository path written in backticks there (``docs/x.md``, ``benchmarks/x.py``, ``configs/x.yaml``...)
  exists;
- every RESULTS.md section cited by name (``benchmarks/RESULTS.md``, "Name") in the docs, the code, the
  benchmarks, the configs and the tests is a heading of benchmarks/RESULTS.md (the name may be the start of a
  longer heading).
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")), ROOT / "benchmarks" / "RESULTS.md"]
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
CODE_PATH = re.compile(r"`((?:docs|benchmarks|configs|core|plugins|examples|tests)/[A-Za-z0-9_./-]+)`")
CITED_SECTION = re.compile(r'RESULTS\.md`{0,2}\)?[,:]?\s+(?:section\s+)?"([^"]+)"')


def _without_code_blocks(text: str) -> str:
    return re.sub(r"^(```|~~~).*?^\1", "", text, flags=re.S | re.M)


def slug(heading: str) -> str:
    """GitHub's anchor of a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"`|\*\*|\*", "", heading.strip().lower())
    text = re.sub(r"[^\w\- ]", "", text, flags=re.U)
    return text.replace(" ", "-")


def headings(path: Path) -> list[str]:
    return [m.group(2).strip() for m in re.finditer(r"^(#{1,6})\s+(.*)$", _without_code_blocks(path.read_text()),
                                                      flags=re.M)]


def anchors(path: Path) -> set[str]:
    seen: dict[str, int] = {}
    out = set()
    for h in headings(path):
        s = slug(h)
        n = seen.get(s, 0)
        out.add(s if n == 0 else f"{s}-{n}")
        seen[s] = n + 1
    return out


def test_slug_follows_github():
    assert slug("How to read a verdict") == "how-to-read-a-verdict"
    assert slug("The run directory, the ledger and the run history") == "the-run-directory-the-ledger-and-the-run-history"
    assert slug("Comparative studies: `suspid study`") == "comparative-studies-suspid-study"


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_resolve(doc: Path):
    bad = []
    for target in LINK.findall(_without_code_blocks(doc.read_text())):
        if re.match(r"^[a-z][a-z0-9+.-]*:", target):   # http:, https:, mailto:
            continue
        path, _, anchor = target.partition("#")
        dest = (doc.parent / path).resolve() if path else doc
        if not dest.exists():
            bad.append(f"{target}: no such file")
        elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
            bad.append(f"{target}: no heading with anchor #{anchor} in {dest.relative_to(ROOT)}")
    assert not bad, f"{doc.relative_to(ROOT)}: " + "; ".join(bad)


@pytest.mark.parametrize("doc", DOCS, ids=lambda p: str(p.relative_to(ROOT)))
def test_paths_in_backticks_exist(doc: Path):
    missing = sorted({p for p in CODE_PATH.findall(doc.read_text())
                      if not any(c in p for c in "*<>{}") and not (ROOT / p.rstrip("/.")).exists()})
    assert not missing, f"{doc.relative_to(ROOT)} names paths that do not exist: {missing}"


def _citing_files() -> list[Path]:
    files = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
    for pattern in ("core/**/*.py", "plugins/**/*.py", "benchmarks/*.py", "tests/*.py", "configs/*.yaml"):
        files += sorted(ROOT.glob(pattern))
    return [f for f in files if f != Path(__file__)]


def missing_sections(text: str, known: list[str]) -> list[str]:
    """The section names ``text`` cites after RESULTS.md that start no heading of ``known``."""
    names = [re.sub(r"\s+", " ", m.group(1)).strip() for m in CITED_SECTION.finditer(text)]
    return [n for n in names if not any(h.startswith(n) for h in known)]


def test_cited_results_sections_exist():
    known = [re.sub(r"\s+", " ", h) for h in headings(ROOT / "benchmarks" / "RESULTS.md")]
    bad = [f"{f.relative_to(ROOT)}: \"{name}\"" for f in _citing_files()
           for name in missing_sections(f.read_text(encoding="utf-8"), known)]
    assert not bad, "sections of benchmarks/RESULTS.md cited but not found: " + "; ".join(bad)


def test_the_citation_check_reads_the_forms_in_use():
    """The forms the docs and docstrings use are read, a line break inside the name included; a missing one is
    caught, and a mention without a name is no citation."""
    text = ('(`benchmarks/RESULTS.md`, "EGO") ``benchmarks/RESULTS.md``, "Table 1 analogue" '
            '`benchmarks/RESULTS.md`, section "Discrepancy\n  workflow" (RESULTS.md, "exudyn train\nmodel: modes") '
            '`benchmarks/RESULTS.md`, "Gone"; RESULTS.md (its figures)')
    known = ["EGO", "Table 1 analogue (q = 7)", "Discrepancy workflow", "exudyn train model: modes, stability"]
    assert missing_sections(text, known) == ["Gone"]


def test_the_readme_maps_every_docs_page():
    """The README's map of docs/ names every page, so that none is found only by chance."""
    linked = {Path(t.partition("#")[0]).name for t in LINK.findall((ROOT / "README.md").read_text())
              if t.startswith("docs/")}
    pages = {p.name for p in (ROOT / "docs").glob("*.md")}
    assert not pages - linked, f"docs pages the README does not link: {sorted(pages - linked)}"
