"""The results page opens with a scannable targets table (docs/results/README.md, "Against the targets"): no cell
longer than 200 characters, and every row links to a section of the page that holds its details and command."""

from __future__ import annotations

import re
import unicodedata
from pathlib import Path

PAGE = Path(__file__).parents[1] / "docs" / "results" / "README.md"
HEADING = "## Against the targets"
MAX_CELL = 200
MAX_BEFORE = 800  # characters of the page above the targets heading


def slugify(text: str) -> str:
    """Python-Markdown's toc slug (MkDocs' default): the heading's text, ASCII, punctuation dropped, lowercase,
    runs of spaces and hyphens to one '-'."""
    text = unicodedata.normalize("NFKD", text).encode("ascii", "ignore").decode("ascii")
    text = re.sub(r"[^\w\s-]", "", text).strip().lower()
    return re.sub(r"[-\s]+", "-", text)


def heading_text(line: str) -> str:
    """A heading's visible text: the markup of links, code and emphasis removed."""
    text = line.lstrip("#").strip()
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", text)
    return re.sub(r"[`*_]", "", text)


def anchors(markdown: str) -> set[str]:
    """The ids the page's headings get: an explicit `{#id}`, else the slug (a repeated slug gets _1, _2, ...)."""
    found: set[str] = set()
    fenced = False
    for line in markdown.splitlines():
        if line.startswith("```"):
            fenced = not fenced
        if fenced or not re.match(r"#{1,6} ", line):
            continue
        explicit = re.search(r"\{[^}]*#([\w-]+)[^}]*\}\s*$", line)
        if explicit:
            found.add(explicit.group(1))
            continue
        slug = base = slugify(heading_text(line))
        n = 0
        while slug in found:
            n += 1
            slug = f"{base}_{n}"
        found.add(slug)
    return found


def split_row(line: str) -> list[str]:
    """A table row's cells; a pipe escaped as \\| or inside a code span does not split."""
    cells, cell, code = [], "", False
    body = line.strip().removeprefix("|").removesuffix("|")
    i = 0
    while i < len(body):
        ch = body[i]
        if ch == "\\" and i + 1 < len(body) and body[i + 1] == "|":
            cell += "|"
            i += 2
            continue
        if ch == "`":
            code = not code
        if ch == "|" and not code:
            cells.append(cell.strip())
            cell = ""
        else:
            cell += ch
        i += 1
    cells.append(cell.strip())
    return cells


def targets_table(markdown: str) -> list[list[str]]:
    """The rows (header and separator left out) of the first table under the targets heading."""
    lines = markdown.splitlines()
    start = lines.index(HEADING)
    rows: list[str] = []
    for line in lines[start + 1 :]:
        if line.startswith("|"):
            rows.append(line)
        elif rows or line.startswith("#"):
            break
    assert len(rows) > 2, f"no table under {HEADING!r}"
    assert re.fullmatch(r"\|(\s*:?-+:?\s*\|)+", rows[1].replace(" ", "")), "the table's second line is not a separator"
    return [split_row(row) for row in [rows[0], *rows[2:]]]


def test_the_targets_table_opens_the_page() -> None:
    """The targets are the page's first section, under at most a short paragraph: no commit history before them."""
    markdown = PAGE.read_text(encoding="utf-8")
    sections = [line for line in markdown.splitlines() if line.startswith("## ")]
    assert sections[0] == HEADING
    before = markdown[: markdown.index(HEADING)]
    assert len(before) <= MAX_BEFORE, f"{len(before)} characters before the targets table (at most {MAX_BEFORE})"


def test_no_cell_of_the_targets_table_is_over_200_characters() -> None:
    rows = targets_table(PAGE.read_text(encoding="utf-8"))
    long = [(row[0][:40], len(cell)) for row in rows for cell in row if len(cell) > MAX_CELL]
    assert not long, f"cells over {MAX_CELL} characters (row, length): {long}"


def test_every_row_of_the_targets_table_links_to_a_section_of_the_page() -> None:
    markdown = PAGE.read_text(encoding="utf-8")
    header, *rows = targets_table(markdown)
    assert all(len(row) == len(header) for row in rows), "a row with a different number of cells than the header"
    ids = anchors(markdown)
    for row in rows:
        links = re.findall(r"\]\(#([^)\s]+)\)", " | ".join(row))
        assert links, f"row {row[0]!r} links to no section of the page"
        missing = [link for link in links if link not in ids]
        assert not missing, f"row {row[0]!r} links to {missing}, which no heading of the page has"


def test_the_slug_follows_mkdocs() -> None:
    assert slugify("A person's registration bias (beside the paper)") == "a-persons-registration-bias-beside-the-paper"
    assert slugify("Exact marks: learning curves (Fig. 3, 5, 9)") == "exact-marks-learning-curves-fig-3-5-9"
    assert slugify("Fig. 7, the other reading: label noise") == "fig-7-the-other-reading-label-noise"
