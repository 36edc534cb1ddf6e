"""Readers for the Oxford VGG "Model House" data in ../shared/data/vgg-house (real P, corners, lines)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from core.camera import Camera

WIDTH, HEIGHT = 768, 576
N_VIEWS = 10


def _matches(path: Path) -> np.ndarray:
    rows = [
        [-1 if tok == "*" else int(tok) for tok in line.split()]
        for line in path.read_text().splitlines()
        if line.strip()
    ]
    return np.array(rows, dtype=int)


@dataclass(frozen=True)
class View:
    P: np.ndarray  # (3, 4) as given (scene at negative depth under the det rule)
    corners_uv: np.ndarray  # (Nc, 2)
    lines_uv: np.ndarray  # (Nl, 2, 2)


@dataclass(frozen=True)
class House:
    views: list[View]
    points: np.ndarray  # (Np, 3) 3D points
    lines: np.ndarray  # (Nl, 2, 3) 3D segments
    point_matches: np.ndarray  # (Np, 10) corner index per view, −1 where unseen
    line_matches: np.ndarray  # (Nl, 10) line index per view, −1 where unseen

    def camera(self, v: int) -> Camera:
        """View v's camera; the reconstruction's world is reflected, so the sign comes from the points."""
        return Camera(self.views[v].P, WIDTH, HEIGHT, in_front=self.points)

    def point_pairs(self, v: int) -> tuple[np.ndarray, np.ndarray]:
        """Matched (X (N, 3), uv (N, 2)) of view v."""
        idx = self.point_matches[:, v]
        seen = idx >= 0
        return self.points[seen], self.views[v].corners_uv[idx[seen]]

    def line_pairs(self, v: int) -> tuple[np.ndarray, np.ndarray]:
        """Matched (3D segments (N, 2, 3), 2D segments (N, 2, 2)) of view v."""
        idx = self.line_matches[:, v]
        seen = idx >= 0
        return self.lines[seen], self.views[v].lines_uv[idx[seen]]


def load_house(root: Path) -> House:
    views = []
    for v in range(N_VIEWS):
        P = np.loadtxt(root / f"house.{v:03d}.P")
        corners = np.loadtxt(root / f"house.{v:03d}.corners")
        lines = np.loadtxt(root / f"house.{v:03d}.lines")[:, :4].reshape(-1, 2, 2)
        views.append(View(P, corners, lines))
    return House(
        views,
        np.loadtxt(root / "house.p3d"),
        np.loadtxt(root / "house.l3d").reshape(-1, 2, 3),
        _matches(root / "house.nview-corners"),
        _matches(root / "house.nview-lines"),
    )
