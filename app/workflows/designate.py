"""Designate a target: click the video → the 3D point on the database's surfaces, for the robot.

The pixel's ray (through C) is cast against every database object at its database pose; the
first surface met is the target, given in world coordinates (metres) with the object's name and
the surface normal. Nothing is written to the database: the targets are shown and copied.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from .base import Marks, Workflow, WorkflowError, as_pixel

__all__ = ["Target", "DesignateTarget"]


@dataclass(frozen=True)
class Target:
    """A designated point: uv (2,) clicked; X_world (3,) metres; object name; range from the
    camera's centre (metres); outward surface normal (3,)."""

    uv: np.ndarray
    X_world: np.ndarray
    object: str
    range_m: float
    normal: np.ndarray

    def text(self) -> str:
        """Copyable text: ``x y z`` in metres (world frame)."""
        x, y, z = self.X_world
        return f"{x:.4f} {y:.4f} {z:.4f}"


class DesignateTarget(Workflow):
    name = "designate"
    title = "Designate target"
    actions = ("click", "clear", "accept", "cancel")

    def __init__(self, site, client: str = "operator"):
        super().__init__(site, client)
        self.targets: list[Target] = []
        self.state = "click"

    def click(self, uv) -> Target:
        """Cast the clicked pixel's ray; the first database surface it meets is the target."""
        p = as_pixel(uv)
        with self.lock:
            self._check_open()
            cam = self.site.camera
            origin, d = cam.rays(p.reshape(1, 2))
            hit = self.site.raycast(origin, d[0])
            if hit is None:
                raise WorkflowError(
                    f"the pixel ({p[0]:.0f}, {p[1]:.0f}) sees no object of the database; click on an object or the table"
                )
            t = Target(p, hit.X_world, hit.name, hit.distance_m, hit.normal)
            self.targets.append(t)
            self.message = f"Target on {hit.name}: {t.text()} m"
            return t

    def clear(self) -> None:
        """Forget the targets designated so far."""
        with self.lock:
            self.targets = []
            self.message = ""

    def accept(self) -> None:
        """Close the workflow (the targets stay in ``targets``; nothing is written)."""
        with self.lock:
            self._check_open()
            self.accepted = True
            self.state = "accepted"

    @property
    def next_step(self) -> str:
        if self.finished:
            return "Done."
        if self.targets:
            return f"Target: {self.targets[-1].text()} m on {self.targets[-1].object}. Click another point, or Done."
        return "Click a point on an object or the table in the video."

    def marks(self) -> Marks:
        with self.lock:
            cam = self.site.camera
            m = Marks()
            if self.targets:
                X = np.array([t.X_world for t in self.targets])
                m.targets = cam.project(X)
                m.labels = [(uv, f"T{i + 1}") for i, uv in enumerate(m.targets)]
            return m

    def summary(self) -> dict[str, Any]:
        with self.lock:
            return {"targets": [{"object": t.object, "X_world": t.X_world.tolist(), "range_m": t.range_m} for t in self.targets]}
