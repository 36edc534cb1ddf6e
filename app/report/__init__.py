"""The demo report's machinery: the paper's tables as data (``paper``), Markdown tables and a
report writer (``markdown``), and matplotlib figures drawn over the paper's (``plots``)."""

from .markdown import ReportWriter, format_value, markdown_table, side_by_side
from .paper import FIGURE_CLAIMS, TABLE_III_1, TABLE_III_2, TABLE_V_1, TRUE_DEPTH_CM, PaperTable, depth_errors_cm

__all__ = [
    "ReportWriter",
    "format_value",
    "markdown_table",
    "side_by_side",
    "FIGURE_CLAIMS",
    "TABLE_III_1",
    "TABLE_III_2",
    "TABLE_V_1",
    "TRUE_DEPTH_CM",
    "PaperTable",
    "depth_errors_cm",
]
