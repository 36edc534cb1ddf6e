"""ViSP ``.cao`` CAD models: read into a ``BRep``, write a ``BRep`` back.

The format (ViSP's ``vpMbTracker::loadCAOModel``), plain text, ``#`` starts a comment::

    V1                                  # or V2: points carry two extra integers (ignored)
    load("other.cao", t=[0.1; 0; 0], tu=[0; 0; 90deg])   # optional includes, any number
    N                                   # points, then N lines "X Y Z" (metres)
    L                                   # lines, then L lines "i j"
    FL                                  # faces from lines, "n l1 ... ln"
    FP                                  # faces from points, "n p1 ... pn" (CCW seen from outside)
    C                                   # cylinders, "i j radius" (axis between points i and j)
    K                                   # circles, "radius centre p1 p2" (p1, p2 span its plane)

Each record is one line; what follows its numbers is a comment, except ``name=…``,
``useLod=…``, ``minLineLengthThreshold=…`` and ``minPolygonAreaThreshold=…``, which are checked
and then dropped (mcit draws every edge). The cylinder and circle blocks may be absent (old files).
``load(path, t=[x; y; z], tu=[θux; θuy; θuz])`` includes a model whose points map into this file's
frame by ``X = R(θu) X_included + t`` (θu in radians, or with a ``deg``/``rad`` suffix); a
relative path is relative to the including file.

Reading into a ``BRep``: the vertices are the points that lines and faces use (points that only
define a cylinder's axis or a circle are not vertices); the edges are every face's sides and
every line, each once; faces from lines are chained into vertex loops. Bad input raises
``CaoError`` naming the file, the line and the problem.

Writing: every face whose sides are all model edges becomes a face from points, the other
edges become lines, cylinders and circles get their defining points appended. A cone (two radii)
has no ``.cao`` form: writing one raises ``ValueError``.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import IO

import numpy as np

from core.brep import BRep, Circle, Revolution
from core.transforms import exp_so3, make_T

__all__ = ["CaoError", "read_cao", "write_cao", "cao_text", "concat_breps"]

_PARAM = re.compile(r"(name|useLod|minLineLengthThreshold|minPolygonAreaThreshold)=(\"[^\"]*\"|\S+)")
_MAX_COUNT = 1_000_000


class CaoError(ValueError):
    """A malformed ``.cao`` file; the message is ``file:line: problem``."""


class _Lines:
    """The file's meaningful lines with their numbers (comments and blank lines dropped)."""

    def __init__(self, path: Path, text: str):
        self.path = path
        self.items: list[tuple[int, str]] = []
        for number, raw in enumerate(text.splitlines(), start=1):
            line = raw.split("#", 1)[0].strip()
            if line:
                self.items.append((number, line))
        self.pos = 0
        self.last_line = len(text.splitlines())

    def error(self, number: int, problem: str) -> CaoError:
        return CaoError(f"{self.path}:{number}: {problem}")

    def peek(self) -> tuple[int, str] | None:
        return self.items[self.pos] if self.pos < len(self.items) else None

    def next(self, what: str) -> tuple[int, str]:
        item = self.peek()
        if item is None:
            raise CaoError(f"{self.path}:{self.last_line}: the file ends where {what} was expected")
        self.pos += 1
        return item


def _numbers(lines: _Lines, number: int, line: str, count: int, kinds: str, what: str) -> tuple[list, str]:
    """The first ``count`` whitespace tokens as numbers (kinds: 'i' int, 'f' float per token) and the rest."""
    tokens = line.split()
    if len(tokens) < count:
        raise lines.error(number, f"{what}: expected {count} numbers, got {len(tokens)} ({line!r})")
    out = []
    for k, (tok, kind) in enumerate(zip(tokens[:count], kinds)):
        try:
            v = int(tok) if kind == "i" else float(tok)
        except ValueError:
            expected = "an integer" if kind == "i" else "a number"
            raise lines.error(number, f"{what}: value {k + 1} is {tok!r}, {expected} expected") from None
        if kind == "f" and not np.isfinite(v):
            raise lines.error(number, f"{what}: value {k + 1} is not finite ({tok})")
        out.append(v)
    rest = line.split(None, count)[count] if len(tokens) > count else ""
    return out, rest


def _check_params(lines: _Lines, number: int, rest: str) -> None:
    for key, value in _PARAM.findall(rest):
        value = value.strip('"')
        if key == "name" and not value:
            raise lines.error(number, "name= is empty")
        if key == "useLod" and value.lower() not in ("true", "false", "1", "0"):
            raise lines.error(number, f"useLod={value!r}: true, false, 1 or 0 expected")
        if key.startswith("min"):
            try:
                float(value)
            except ValueError:
                raise lines.error(number, f"{key}={value!r}: a number expected") from None


def _count(lines: _Lines, what: str) -> int:
    number, line = lines.next(f"the number of {what}")
    (n,), _ = _numbers(lines, number, line, 1, "i", f"number of {what}")
    if n < 0 or n > _MAX_COUNT:
        raise lines.error(number, f"number of {what} is {n}; expected 0..{_MAX_COUNT}")
    return n


def _index(lines: _Lines, number: int, i: int, n: int, what: str) -> int:
    if not 0 <= i < n:
        raise lines.error(number, f"{what} index {i} out of range 0..{n - 1}")
    return i


def _parse_vector(lines: _Lines, number: int, text: str, key: str, angles: bool) -> np.ndarray:
    parts = [p.strip() for p in text.split(";")]
    if len(parts) != 3:
        raise lines.error(number, f"load(): {key}=[...] needs 3 values separated by ';', got {text!r}")
    out = []
    for p in parts:
        scale = 1.0
        if angles and p.endswith("deg"):
            p, scale = p[:-3], np.pi / 180.0
        elif angles and p.endswith("rad"):
            p = p[:-3]
        try:
            out.append(float(p) * scale)
        except ValueError:
            raise lines.error(number, f"load(): {key}=[...] value {p!r} is not a number") from None
    return np.array(out)


def _parse_load(lines: _Lines, number: int, line: str) -> tuple[Path, np.ndarray]:
    m = re.fullmatch(r'load\s*\(\s*"([^"]+)"\s*((?:,[^)]*)?)\)\s*', line)
    if not m:
        raise lines.error(number, f'malformed include; expected load("file.cao", t=[x; y; z], tu=[a; b; c]), got {line!r}')
    target = Path(m.group(1))
    if not target.is_absolute():
        target = lines.path.parent / target
    t = np.zeros(3)
    tu = np.zeros(3)
    for param in (p.strip() for p in m.group(2).split(",")[1:]):
        pm = re.fullmatch(r"(t|tu)\s*=\s*\[([^\]]*)\]", param)
        if not pm:
            raise lines.error(number, f"load(): unknown parameter {param!r}; use t=[x; y; z] and tu=[a; b; c]")
        if pm.group(1) == "t":
            t = _parse_vector(lines, number, pm.group(2), "t", angles=False)
        else:
            tu = _parse_vector(lines, number, pm.group(2), "tu", angles=True)
    return target.resolve(), make_T(exp_so3(tu), t)


def _chain(lines: _Lines, number: int, segments: list[tuple[int, int]]) -> list[int]:
    """Vertex loop from a face's lines, in the given order; CaoError when they do not close."""
    if len(segments) < 3:
        raise lines.error(number, f"a face needs at least 3 lines, got {len(segments)}")
    a, b = segments[0]
    c, d = segments[1]
    loop = [b, a] if a in (c, d) and b not in (c, d) else [a, b]
    for k, (c, d) in enumerate(segments[1:], start=2):
        if c == loop[-1]:
            loop.append(d)
        elif d == loop[-1]:
            loop.append(c)
        else:
            raise lines.error(number, f"line {k} of the face does not continue from point {loop[-1]}: the face's lines must form a loop")
    if loop[-1] != loop[0]:
        raise lines.error(number, f"the face's lines do not close: they end at point {loop[-1]}, not {loop[0]}")
    loop.pop()
    if len(set(loop)) != len(loop):
        raise lines.error(number, "the face's lines visit a point twice")
    return loop


def concat_breps(models: list[BRep]) -> BRep:
    """One model holding several (vertex indices shifted); they share one frame."""
    Vs, Es, Fs, solids, circles = [], [], [], [], []
    offset = 0
    for m in models:
        Vs.append(m.vertices)
        Es.append(m.edges + offset)
        Fs += [tuple(v + offset for v in f) for f in m.faces]
        solids += list(m.solids)
        circles += list(m.circles)
        offset += len(m.vertices)
    return BRep(np.vstack(Vs).reshape(-1, 3), np.vstack(Es).reshape(-1, 2), tuple(Fs), tuple(solids), tuple(circles))


def _read(path: Path, stack: tuple[Path, ...]) -> BRep | None:
    try:
        text = path.read_text()
    except UnicodeDecodeError:
        raise CaoError(f"{path}:1: not a text file") from None
    except OSError as exc:
        raise CaoError(f"{path}: cannot read: {exc.strerror or exc}") from None
    lines = _Lines(path, text)
    number, head = lines.next("the version line 'V1'")
    m = re.fullmatch(r"V(\d+)(\s.*)?", head)
    if not m:
        raise lines.error(number, f"the first line must be the version 'V1' (or V2), got {head!r}")
    version = int(m.group(1))
    if version not in (1, 2):
        raise lines.error(number, f"unsupported .cao version V{version}; mcit reads V1 and V2")
    parts: list[BRep] = []
    while (item := lines.peek()) is not None and item[1][:1] in ("l", "L"):
        number, line = lines.next("load(...)")
        target, T = _parse_load(lines, number, line)
        if target in stack:
            raise lines.error(number, f"cyclic include: {target} is already being read")
        if not target.is_file():
            raise lines.error(number, f"included file not found: {target}")
        sub = _read(target, stack + (target,))
        if sub is not None:
            parts.append(sub.transformed(T))
    n_points = _count(lines, "points")
    P = np.zeros((n_points, 3))
    for k in range(n_points):
        number, line = lines.next(f"point {k} of {n_points}")
        n_num = 5 if version == 2 else 3
        values, _ = _numbers(lines, number, line, n_num, "fffii"[:n_num], f"point {k}")
        P[k] = values[:3]
    n_lines = _count(lines, "lines")
    segs: list[tuple[int, int]] = []
    for k in range(n_lines):
        number, line = lines.next(f"line {k} of {n_lines}")
        (i, j), rest = _numbers(lines, number, line, 2, "ii", f"line {k}")
        i, j = _index(lines, number, i, n_points, "point"), _index(lines, number, j, n_points, "point")
        if i == j:
            raise lines.error(number, f"line {k} joins point {i} to itself")
        _check_params(lines, number, rest)
        segs.append((i, j))
    loops: list[list[int]] = []
    for what, by_lines in (("faces from lines", True), ("faces from points", False)):
        n_faces = _count(lines, what)
        for k in range(n_faces):
            number, line = lines.next(f"face {k} of the {what}")
            (n,), _ = _numbers(lines, number, line, 1, "i", f"face {k}")
            if n < 3:
                raise lines.error(number, f"face {k} has {n} {'lines' if by_lines else 'points'}; a face needs at least 3")
            values, rest = _numbers(lines, number, line, n + 1, "i" * (n + 1), f"face {k}")
            _check_params(lines, number, rest)
            if by_lines:
                idx = [_index(lines, number, i, n_lines, "line") for i in values[1:]]
                loops.append(_chain(lines, number, [segs[i] for i in idx]))
            else:
                loop = [_index(lines, number, i, n_points, "point") for i in values[1:]]
                if len(set(loop)) != len(loop):
                    raise lines.error(number, f"face {k} lists a point twice")
                loops.append(loop)
    solids: list[Revolution] = []
    circles: list[Circle] = []
    if lines.peek() is not None:
        for k in range(_count(lines, "cylinders")):
            number, line = lines.next(f"cylinder {k}")
            (i, j, r), rest = _numbers(lines, number, line, 3, "iif", f"cylinder {k}")
            i, j = _index(lines, number, i, n_points, "point"), _index(lines, number, j, n_points, "point")
            _check_params(lines, number, rest)
            if r <= 0:
                raise lines.error(number, f"cylinder {k}: radius must be positive, got {r}")
            try:
                solids.append(Revolution(P[i], P[j], r, r))
            except ValueError as exc:
                raise lines.error(number, f"cylinder {k}: {exc}") from None
    if lines.peek() is not None:
        for k in range(_count(lines, "circles")):
            number, line = lines.next(f"circle {k}")
            (r, c, i, j), rest = _numbers(lines, number, line, 4, "fiii", f"circle {k}")
            c, i, j = (_index(lines, number, v, n_points, "point") for v in (c, i, j))
            _check_params(lines, number, rest)
            normal = np.cross(P[i] - P[c], P[j] - P[c])
            if r <= 0 or np.linalg.norm(normal) <= 1e-12 * max(1.0, float(np.abs(P).max())) ** 2:
                raise lines.error(number, f"circle {k}: needs a positive radius and a centre and two points not on one line")
            circles.append(Circle(P[c], normal, r))
    if (item := lines.peek()) is not None:
        raise lines.error(item[0], f"unexpected content after the last block: {item[1]!r}")
    used = sorted({v for loop in loops for v in loop} | {v for s in segs for v in s})
    if not used and not solids and not circles and not parts:
        raise CaoError(f"{path}:{lines.last_line}: the model has no lines, faces, cylinders or circles")
    remap = {old: new for new, old in enumerate(used)}
    edges: dict[tuple[int, int], None] = {}
    for loop in loops:
        for a, b in zip(loop, loop[1:] + loop[:1]):
            edges.setdefault((min(remap[a], remap[b]), max(remap[a], remap[b])), None)
    for a, b in segs:
        edges.setdefault((min(remap[a], remap[b]), max(remap[a], remap[b])), None)
    if used or solids or circles:
        parts.append(
            BRep(
                P[used].reshape(-1, 3),
                np.array(list(edges), dtype=np.int64).reshape(-1, 2),
                tuple(tuple(remap[v] for v in loop) for loop in loops),
                tuple(solids),
                tuple(circles),
            )
        )
    return concat_breps(parts) if parts else None


def read_cao(path: str | Path) -> BRep:
    """Read a ViSP ``.cao`` model (with its ``load(...)`` includes) into a ``BRep`` in its frame.

    Raises
    ------
    CaoError (a ValueError) naming the file, the line and the problem.
    """
    path = Path(path).resolve()
    model = _read(path, (path,))
    if model is None:
        raise CaoError(f"{path}: the model is empty")
    return model


def _fmt(x: float) -> str:
    return repr(float(x))


def cao_text(model: BRep, comment: str = "") -> str:
    """The ``.cao`` (V1) text of a model; see the module docstring. ValueError for cones."""
    for s in model.solids:
        if not s.is_cylinder:
            raise ValueError(f"a .cao model has cylinders only; this model has a cone (radii {s.r0}, {s.r1}): export it as glTF or OBJ")
    edge_set = {(int(a), int(b)) for a, b in model.edges}
    faces = []
    covered: set[tuple[int, int]] = set()
    for f in model.faces:
        sides = {(min(a, b), max(a, b)) for a, b in zip(f, f[1:] + f[:1])}
        if sides <= edge_set:
            faces.append(f)
            covered |= sides
    lines = [(a, b) for a, b in map(tuple, model.edges.tolist()) if (a, b) not in covered]
    points = [tuple(p) for p in model.vertices.tolist()]
    cylinders = []
    for s in model.solids:
        cylinders.append((len(points), len(points) + 1, s.r0))
        points += [tuple(s.p0), tuple(s.p1)]
    circles = []
    for c in model.circles:
        e1, e2 = c.basis()
        circles.append((c.radius, len(points), len(points) + 1, len(points) + 2))
        points += [tuple(c.centre), tuple(c.centre + c.radius * e1), tuple(c.centre + c.radius * e2)]
    out = ["V1"]
    if comment:
        out += [f"# {line}" for line in comment.splitlines()]
    out += ["# 3D points", str(len(points))]
    out += [" ".join(_fmt(x) for x in p) for p in points]
    out += ["# 3D lines", str(len(lines))] + [f"{a} {b}" for a, b in lines]
    out += ["# Faces from 3D lines", "0"]
    out += ["# Faces from 3D points", str(len(faces))] + [" ".join(str(v) for v in (len(f),) + tuple(f)) for f in faces]
    out += ["# 3D cylinders", str(len(cylinders))] + [f"{i} {j} {_fmt(r)}" for i, j, r in cylinders]
    out += ["# 3D circles", str(len(circles))] + [f"{_fmt(r)} {c} {i} {j}" for r, c, i, j in circles]
    return "\n".join(out) + "\n"


def write_cao(model: BRep, path: str | Path | IO[str], comment: str = "") -> None:
    """Write a model as a ViSP ``.cao`` file (see ``cao_text``)."""
    text = cao_text(model, comment)
    if hasattr(path, "write"):
        path.write(text)
    else:
        Path(path).write_text(text)
