"""Markdown for the demo's report: tables (ours beside the paper's) and a small document writer.

``markdown_table`` formats rows of numbers and text as a GitHub-flavoured Markdown table;
``side_by_side`` puts the paper's columns next to ours, row by row; ``ReportWriter`` assembles a
report.md with its PNG figures in one folder.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

__all__ = ["format_value", "markdown_table", "side_by_side", "ReportWriter"]


def format_value(v: Any, digits: int = 3) -> str:
    """A table cell: numbers with ``digits`` significant digits (— for None or NaN), text as is."""
    if v is None:
        return "—"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "—"
        if v == 0.0 or math.isinf(v):
            return str(v)
        if 1e-3 <= abs(v) < 1e5:
            decimals = max(0, digits - 1 - int(math.floor(math.log10(abs(v)))))
            return f"{v:.{decimals}f}"
        return f"{v:.{max(digits - 1, 0)}e}"
    return str(v).replace("|", "\\|").replace("\n", " ")


def markdown_table(
    headers: Sequence[str], rows: Sequence[Sequence[Any]], *, digits: int = 3, align: str | None = None
) -> str:
    """A Markdown table.

    headers : column titles. rows : rows of cells (numbers, text, None). digits : significant
    digits of floats. align : one letter per column, "l", "r" or "c" (default: numbers right,
    text left, judged from the first row).
    """
    n = len(headers)
    if n == 0:
        raise ValueError("a table needs at least one column")
    for i, r in enumerate(rows):
        if len(r) != n:
            raise ValueError(f"row {i} has {len(r)} cells but the table has {n} columns ({list(headers)})")
    if align is None:
        first = rows[0] if rows else [""] * n
        align = "".join("r" if isinstance(c, (int, float)) and not isinstance(c, bool) else "l" for c in first)
    if len(align) != n or set(align) - set("lrc"):
        raise ValueError(f"align must be {n} letters among l, r, c; got {align!r}")
    rule = {"l": ":---", "r": "---:", "c": ":---:"}
    lines = [
        "| " + " | ".join(format_value(h) for h in headers) + " |",
        "|" + "|".join(rule[a] for a in align) + "|",
    ]
    for r in rows:
        lines.append("| " + " | ".join(format_value(c, digits) for c in r) + " |")
    return "\n".join(lines) + "\n"


def side_by_side(
    key: str,
    columns: Sequence[str],
    paper: dict[Any, Sequence[Any]],
    ours: dict[Any, Sequence[Any]],
    *,
    digits: int = 3,
) -> str:
    """One row per key (e.g. a distance), each column as "paper | ours" pairs.

    key : title of the key column. columns : names of the compared quantities. paper, ours :
    key → values in ``columns`` order (a key missing on one side shows —).
    """
    headers = [key] + [f"{c} ({who})" for c in columns for who in ("paper", "ours")]
    keys = sorted(set(paper) | set(ours), key=lambda k: (isinstance(k, str), k))
    rows = []
    for k in keys:
        p = list(paper.get(k, [None] * len(columns)))
        o = list(ours.get(k, [None] * len(columns)))
        if len(p) != len(columns) or len(o) != len(columns):
            raise ValueError(f"row {k!r}: expected {len(columns)} values per side, got {len(p)} and {len(o)}")
        rows.append([k] + [v for pair in zip(p, o) for v in pair])
    return markdown_table(headers, rows, digits=digits)


class ReportWriter:
    """Builds a Markdown report and its PNG figures in ``out_dir``.

    >>> w = ReportWriter(tmp); w.heading("Results"); w.table(["a"], [[1]]); w.write()
    """

    def __init__(self, out_dir: str | Path, title: str = "Report"):
        self.out_dir = Path(out_dir)
        self.parts: list[str] = [f"# {title}\n"]
        self.figures: list[Path] = []

    def heading(self, text: str, level: int = 2) -> None:
        if not 1 <= level <= 6:
            raise ValueError(f"a Markdown heading level is 1 … 6, got {level}")
        self.parts.append(f"{'#' * level} {text}\n")

    def paragraph(self, text: str) -> None:
        self.parts.append(text.strip() + "\n")

    def table(
        self, headers: Sequence[str], rows: Sequence[Sequence[Any]], *, digits: int = 3, caption: str = ""
    ) -> None:
        if caption:
            self.parts.append(f"*{caption}*\n")
        self.parts.append(markdown_table(headers, rows, digits=digits))

    def markdown(self, text: str) -> None:
        """Append ready-made Markdown (e.g. from ``side_by_side``)."""
        self.parts.append(text.rstrip() + "\n")

    def figure(self, fig, name: str, caption: str = "", dpi: int = 110) -> Path:
        """Save a matplotlib figure as ``name``.png beside the report and link it; closes the figure."""
        import matplotlib.pyplot as plt

        self.out_dir.mkdir(parents=True, exist_ok=True)
        path = self.out_dir / f"{name}.png"
        fig.savefig(path, dpi=dpi, bbox_inches="tight")
        plt.close(fig)
        self.figures.append(path)
        self.parts.append(f"![{caption or name}]({path.name})\n" + (f"\n*{caption}*\n" if caption else ""))
        return path

    def text(self) -> str:
        return "\n".join(self.parts)

    def write(self, name: str = "report.md") -> Path:
        self.out_dir.mkdir(parents=True, exist_ok=True)
        path = self.out_dir / name
        path.write_text(self.text())
        return path
