"""BENCHMARKS.md is a reference (issue 63): one section per benchmark program, under 600 lines, and
every place that cites one of its sections by title (code comments and docstrings, the README,
the docs and their links to the page's anchors) names a section it has."""

import re
import unicodedata
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PAGE = ROOT / "BENCHMARKS.md"
# Where the repository cites the page; this file is left out (its docstring describes the form).
CITING = ["README.md", "docs", "benchmarks", "learn", "liepoisson", "integrators", "paper", "tests"]
# `BENCHMARKS.md, "Title"`, `BENCHMARKS.md ("Title")`, `BENCHMARKS.md, section "Title"`, with
# more titles joined by "and"; the quoted text may run over lines of a comment or docstring.
CITE = re.compile(r'BENCHMARKS\.md`?(?:,\s*(?:section\s+)?|\s*\(\s*)((?:"[^"]+"(?:\s*(?:,|and)\s*)?)+)')


def _headings() -> list[str]:
    headings, fenced = [], False
    for line in PAGE.read_text().splitlines():
        if line.startswith("```"):
            fenced = not fenced
        elif not fenced and (m := re.match(r"#{1,6} (.+)", line)):
            headings.append(m.group(1).strip())
    return headings


def _plain(text: str) -> str:
    return text.replace("`", "").strip()


def _slug(heading: str) -> str:
    # Python-Markdown's `toc` slugify (mkdocs.yml: `toc`), on the heading's text without markup
    text = unicodedata.normalize("NFKD", _plain(heading)).encode("ascii", "ignore").decode("ascii")
    text = re.sub(r"[^\w\s-]", "", text).strip().lower()
    return re.sub(r"[-\s]+", "-", text)


def _citing_files():
    for name in CITING:
        path = ROOT / name
        for file in [path] if path.is_file() else sorted(path.rglob("*")):
            if file.suffix in {".py", ".md"} and file != Path(__file__).resolve():
                yield file


def _flattened(file: Path) -> str:
    # one line of text: comment markers and indentation dropped, so a title can run over lines
    lines = (re.sub(r"^\s*(?:#:?\s?)?", "", line).strip() for line in file.read_text().splitlines())
    return " ".join(lines)


def _citations() -> list[tuple[str, str]]:
    found = []
    for file in _citing_files():
        for m in CITE.finditer(_flattened(file)):
            found += [(str(file.relative_to(ROOT)), t) for t in re.findall(r'"([^"]+)"', m.group(1))]
    # the exploration log's table: script | BENCHMARKS.md (sub)section | finding
    log = ROOT / "benchmarks" / "exploration" / "README.md"
    for line in log.read_text().splitlines():
        if line.startswith("| `"):
            found += [(str(log.relative_to(ROOT)), t) for t in re.findall(r'"([^"]+)"', line.split("|")[2])]
    return found


def test_the_page_is_a_reference_under_600_lines():
    lines = PAGE.read_text().splitlines()
    assert len(lines) < 600, f"BENCHMARKS.md has {len(lines)} lines: superseded figures go to git history"


def test_section_titles_are_unique():
    headings = [_plain(h) for h in _headings()]
    assert len(headings) == len(set(headings)), sorted(h for h in headings if headings.count(h) > 1)


def test_every_benchmark_program_has_a_section():
    programs = sorted(p.name for p in (ROOT / "benchmarks").glob("*.py") if not p.name.startswith("_"))
    text = "\n".join(_headings())
    missing = [p for p in programs if f"`benchmarks/{p}`" not in text]
    assert programs and not missing, missing


def test_every_cited_section_exists():
    headings = [_plain(h) for h in _headings()]
    citations = _citations()
    # the form is found where it is known to be (a check of the search itself)
    assert ("docs/tutorials/air.md", "W7: bodies in air") in citations
    assert ("learn/_training/_body.py", "The vehicle at noise 1e-2 fixed: the inertia estimate in weak form") in citations
    assert ("benchmarks/exploration/README.md", "G-LPNet ablation: why the paper's network stalls on a new algebra") in citations
    broken = [(file, title) for file, title in citations
              if not any(h.startswith(_plain(title)) for h in headings)]
    assert not broken, broken


def test_every_link_to_the_page_has_its_anchor():
    slugs = {_slug(h) for h in _headings()}
    links = [(str(f.relative_to(ROOT)), a) for f in (ROOT / "docs").rglob("*.md")
             for a in re.findall(r"benchmarks\.md#([\w-]+)", f.read_text())]
    assert links
    broken = [(file, anchor) for file, anchor in links if anchor not in slugs]
    assert not broken, broken


def _page_slugs(file: Path) -> set[str]:
    slugs, fenced = set(), False
    for line in file.read_text().splitlines():
        if line.startswith("```"):
            fenced = not fenced
        elif not fenced and (m := re.match(r"#{1,6} (.+)", line)):
            explicit = re.search(r"\{\s*#([\w-]+)\s*\}\s*$", m.group(1))
            slugs.add(explicit.group(1) if explicit else _slug(m.group(1)))
    return slugs


def test_every_cross_reference_to_a_heading_resolves():
    # mkdocs-autorefs links `[text][heading-slug]` in docstrings and pages: a renamed section of
    # the page breaks them (the strict docs build finds it too, but only under -m slow)
    slugs = _page_slugs(PAGE).union(*(_page_slugs(f) for f in (ROOT / "docs").rglob("*.md")))
    targets = [(str(f.relative_to(ROOT)), s) for f in _citing_files()
               for s in re.findall(r"\]\[([a-z0-9_]+(?:-[a-z0-9_]+){3,})\]", f.read_text())]
    assert ("learn/_models/_plus_affine.py", "e5-the-affine-part-fixed-issue-29-benchmarksaffine_partpy") in targets
    broken = [(file, slug) for file, slug in targets if slug not in slugs]
    assert not broken, broken
