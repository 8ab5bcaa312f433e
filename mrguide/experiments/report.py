"""Experiment reports: CSV and markdown tables written whole, run files read back, figures with the
paper's numbers drawn beside ours."""

from __future__ import annotations

import csv
import gzip
import io
from pathlib import Path
from typing import Any

import numpy as np

from mrguide.output_files import write_files_atomically

PAPER_COLOR = "0.35"


def read_csv(path: Path) -> list[dict[str, str]]:
    """The rows of a CSV file, or of its gzip-compressed copy `path.gz` where only that one is there (the run files
    committed under docs/results are stored compressed)."""
    packed = path.with_name(path.name + ".gz")
    with gzip.open(packed, "rt") if packed.exists() and not path.exists() else path.open() as fh:
        return list(csv.DictReader(fh))


def csv_bytes(rows: list[dict[str, Any]], fields: list[str]) -> bytes:
    buf = io.StringIO()
    w = csv.DictWriter(buf, fields, extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    w.writerows(rows)
    return buf.getvalue().encode()


def markdown(rows: list[dict[str, Any]], columns: list[tuple[str, str]]) -> str:
    """A markdown table of `rows` with (key, header) columns; None shows as an em dash."""
    lines = ["| " + " | ".join(h for _, h in columns) + " |", "|" + " --- |" * len(columns)]
    for r in rows:
        lines.append("| " + " | ".join("—" if r.get(k) is None else str(r[k]) for k, _ in columns) + " |")
    return "\n".join(lines) + "\n"


def summary_files(
    intro: str, summary: list[dict[str, Any]], columns: list[tuple[str, str]], rows: list[dict[str, Any]]
) -> dict[str, bytes]:
    """summary.csv, runs.csv and summary.md: `intro`, the summary's table with `columns`, then one row per run."""
    runs_table = markdown(rows, [(k, k.replace("_", " ")) for k in rows[0]])
    return {
        "summary.csv": csv_bytes(summary, list(summary[0])),
        "runs.csv": csv_bytes(rows, list(rows[0])),
        "summary.md": (intro + markdown(summary, columns) + "\n\n" + runs_table).encode(),
    }


def write_report(out: Path, files: dict[str, bytes]) -> None:
    """Write the named report files into `out` together (each whole, via temporary files and renames)."""
    out.mkdir(parents=True, exist_ok=True)
    write_files_atomically({out / name: data for name, data in files.items()})


def _pyplot():
    """matplotlib's pyplot on the file-only Agg backend, imported when the first figure is drawn (the CLI lists the
    experiments without it)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def figure(title: str, xlabel: str, ylabel: str, size: tuple[float, float] = (7.0, 4.0), columns: int = 1):
    """A figure with one axes (or `columns` side by side, sharing the title and the y label)."""
    fig, ax = _pyplot().subplots(1, columns, figsize=size)
    for a in np.atleast_1d(ax):
        a.set(xlabel=xlabel, ylabel=ylabel)
    if columns == 1:
        ax.set_title(title)
    else:
        fig.suptitle(title)
    return fig, ax


def png_bytes(fig) -> bytes:
    buf = io.BytesIO()
    fig.tight_layout()
    fig.savefig(buf, format="png", dpi=120)
    _pyplot().close(fig)
    return buf.getvalue()


def paper_note(ax, text: str) -> None:
    """The paper's figure for this plot, as a boxed note in the corner (when it gives no curve to draw)."""
    ax.text(
        0.99,
        0.02,
        f"paper: {text}",
        transform=ax.transAxes,
        ha="right",
        va="bottom",
        fontsize=8,
        color=PAPER_COLOR,
        bbox={"boxstyle": "round", "fc": "white", "ec": PAPER_COLOR, "alpha": 0.9},
    )
