"""What the database hands out (read-only records) and how values travel to and from JSON.

Arrays are stored as JSON lists (a pose as its 4×4 rows), so that the file can be read with any
SQLite tool; numpy arrays and scalars given to the database are converted on the way in.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

import numpy as np

from core.brep import BRep

__all__ = ["ConflictError", "NotFoundError", "ObjectRecord", "ChangeRecord", "CalibrationRecord", "to_json", "STATUSES"]

STATUSES = ("known", "modelled", "stale")


class ConflictError(RuntimeError):
    """The object changed since the caller read it (its version moved): nothing was written.

    Attributes: ``name``, ``expected_version`` (what the caller had), ``actual_version``.
    """

    def __init__(self, name: str, expected_version: int, actual_version: int | None):
        self.name = name
        self.expected_version = expected_version
        self.actual_version = actual_version
        now = "it was removed" if actual_version is None else f"it is at version {actual_version}"
        super().__init__(
            f"object {name!r} changed since you read it (you had version {expected_version}, {now}); "
            "nothing was written: reload it and redo the change"
        )


class NotFoundError(LookupError):
    """No such object, change or calibration."""

    def __str__(self) -> str:  # LookupError would quote the message
        return str(self.args[0]) if self.args else ""


def _default(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, BRep):
        return value.to_dict()
    if isinstance(value, (set, frozenset, tuple)):
        return list(value)
    if hasattr(value, "_asdict"):
        return value._asdict()
    raise TypeError(
        f"cannot store a {type(value).__name__} in the database (use numbers, strings, lists, dicts, arrays)"
    )


def to_json(value: Any) -> str | None:
    """JSON text of a value (numpy arrays → lists); None stays None. ValueError when not storable."""
    if value is None:
        return None
    try:
        return json.dumps(value, default=_default, separators=(",", ":"))
    except (TypeError, ValueError) as exc:
        raise ValueError(str(exc)) from None


def frozen_array(value: Any, shape: tuple[int, ...]) -> np.ndarray:
    a = np.array(value, dtype=float).reshape(shape)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class ObjectRecord:
    """One object of the site, as read (never mutate it: records are shared by every reader).

    Records compare by identity (they hold arrays); compare ``(id, version)`` to see a change.

    id : int. name : unique among live objects. kind : "box", "cylinder", "polyhedron", ...
    status : "known", "modelled" or "stale". version : bumped by every change (conflict check).
    model : BRep in the object frame (metres). model_id : its row (identical models share one).
    T_world_obj : array, shape (4, 4), read-only. cov : array, shape (6, 6), read-only, or None:
    the pose's covariance as the method that estimated it gave it.
    dims, sigmas : read-only mappings name → metres (dimensions and their standard deviations).
    source : the file the model was imported from, or None. created_at, updated_at : unix seconds.
    """

    id: int
    name: str
    kind: str
    status: str
    version: int
    model: BRep
    model_id: int
    T_world_obj: np.ndarray
    cov: np.ndarray | None
    dims: Mapping[str, float]
    sigmas: Mapping[str, float]
    source: str | None
    created_at: float
    updated_at: float

    @property
    def dimensions(self) -> Mapping[str, float]:
        return self.dims

    @property
    def model_sigma_m(self) -> float:
        """The model's stated uncertainty: σ of each model edge's position (metres), part of every pose's σ
        (issue 27): ``sigmas["model"]`` (``mcit db import --model-sigma-mm``), else the default prior
        (``core.pose.uncertainty.MODEL_PRIOR_M``)."""
        from core.pose.uncertainty import model_sigma_of

        return model_sigma_of(self.sigmas)


@dataclass(frozen=True)
class ChangeRecord:
    """One entry of the history.

    action : "add", "update", "undo", "restore", "remove" or "calibration". object_id /
    calibration_id : what changed. version : the object's version after the change.
    before, after : snapshots of the object (dicts with name, kind, status, model_id,
    T_world_obj, cov, dims, sigmas, removed); before is None for "add".
    clicks, measurements, residuals : what the method used and left (JSON values).
    undoes : the change an undo/restore refers to. seen_at : when the image the change was measured on was
    taken (unix seconds: a ROS image's header stamp, else when mcit received the frame); None when the
    change was not measured on an image.
    """

    id: int
    time: float
    client: str
    method: str
    action: str
    object_id: int | None
    object_name: str | None
    calibration_id: int | None
    version: int | None
    before: dict | None
    after: dict | None
    clicks: Any
    measurements: Any
    residuals: Any
    note: str | None
    undoes: int | None
    seen_at: float | None = None


@dataclass(frozen=True)
class CalibrationRecord:
    """One calibration: kind ("camera": data {"C", "width", "height", ...}; "turret": data
    {"T_world_turret", ...}), its residuals, when, by whom and how."""

    id: int
    kind: str
    data: dict
    residuals: Any
    time: float
    client: str
    method: str


def mapping(text: str) -> Mapping[str, float]:
    return MappingProxyType(json.loads(text))
