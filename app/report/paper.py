"""The source paper's published results, as data, for side-by-side comparison with ours.

Transcribed from shared/paper/source-paper.md (tables verbatim; units as printed). The figures
(III.6, V.1, V.2) have no printed data beyond Table III.2 and the bounds the text states, which
``FIGURE_CLAIMS`` records so a plot can draw them as reference lines.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["PaperTable", "TABLE_III_1", "TABLE_III_2", "TABLE_V_1", "TRUE_DEPTH_CM", "FIGURE_CLAIMS", "depth_errors_cm"]


@dataclass(frozen=True)
class PaperTable:
    """A table of the paper: ``columns`` (names with units) and ``rows`` (tuples of numbers)."""

    name: str
    caption: str
    columns: tuple[str, ...]
    rows: tuple[tuple[float, ...], ...]
    note: str = ""

    def column(self, name: str) -> list[float]:
        """The values of one column, in row order."""
        if name not in self.columns:
            raise KeyError(f"{self.name} has no column {name!r}; it has {list(self.columns)}")
        k = self.columns.index(name)
        return [r[k] for r in self.rows]


TABLE_III_1 = PaperTable(
    "Table III.1",
    "Results obtained with the different interpretation plane (errors of the modelled box)",
    ("distance_m", "width_cm", "height_cm", "length_cm", "volume_dm3"),
    (
        (1.3, 0.67, 0.73, 0.52, 0.20),
        (1.4, 0.66, 0.58, 0.53, 0.19),
        (1.5, 0.55, 0.53, 0.48, 0.14),
        (1.6, 0.37, 0.38, 0.47, 0.13),
    ),
    "Object w × h × l = 9 cm × 14 cm × 9.4 cm; distance object/sensor in metres; the columns are the "
    "errors of the modelled dimensions (cm) and volume (dm³).",
)

TABLE_III_2 = PaperTable(
    "Table III.2",
    "Result in depth for the three methods (cylinder R = 5.1 cm, h = 16.6 cm, true depth 5.1 cm)",
    ("distance_m", "tangential_vc_rf_cm", "bisecting_vc_rf_cm", "tangential_rf_cm"),
    (
        (1.0, 4.8314, 3.5098, 5.6332),
        (1.2, 4.7523, 3.5512, 5.6775),
        (1.4, 4.6765, 4.1416, 4.1501),
        (1.6, 4.6861, 4.3974, 4.0068),
    ),
    "Estimated depth (cm) of the cylinder by (a) tangential planes, camera + range finder, (b) bisecting "
    "planes, camera + range finder, (c) tangential planes, range finder alone. Figure III.6 plots their "
    "error against the true depth, 5.1 cm.",
)
TRUE_DEPTH_CM = 5.1

TABLE_V_1 = PaperTable(
    "Table V.1",
    "Mean value and standard deviation of the errors (g: large motion, p: small motion)",
    ("quantity", "mean_large", "mean_small", "std_large", "std_small"),
    (
        ("tz_m", 0.01378, 0.00563, 0.01268, 0.00233),
        ("R_deg", 0.23342, 0.09810, 0.19033, 0.11136),
    ),
    "Parallelepiped 35 × 23.1 × 13.2 cm at ~2 m, camera 512 × 256, the operator clicking the video; "
    "tz: error of the translation (m), R: error of the rotation angle (°).",
)

# Bounds the paper's text states for its figures (no data points are printed).
FIGURE_CLAIMS = {
    "III.6": {"tangential_vc_rf_max_cm": 0.5},
    "V.1": {"large_noise_free_rotation_deg": 1e-4, "large_noise_free_translation_m": 1e-6},
    "V.2": {
        "large_rotation_max_deg": 0.7,
        "large_translation_max_m": 0.04,
        "small_rotation_max_deg": 0.3,
        "small_translation_max_m": 0.01,
    },
    "IV.2 validity": {"small_motion_max_rotation_deg": 18.0, "small_motion_max_translation_m": 0.05},
}


def depth_errors_cm(method: str) -> list[float]:
    """Figure III.6's curve for one method of Table III.2: estimated depth − 5.1 cm, per distance."""
    return [round(v - TRUE_DEPTH_CM, 4) for v in TABLE_III_2.column(method)]
