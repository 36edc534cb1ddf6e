"""The code's shape, as the project holds it (issue 24's habits): ruff clean and formatted, no import
cycles (imports inside functions count; ``TYPE_CHECKING`` ones do not), no function in ``core/`` over
100 lines outside the compiled kernels."""

from __future__ import annotations

import ast
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
MAX_CORE_FUNCTION_LINES = 100


def _modules() -> dict[str, Path]:
    mods = {}
    for path in sorted([*ROOT.glob("app/**/*.py"), *ROOT.glob("core/**/*.py")]):
        parts = list(path.relative_to(ROOT).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        mods[".".join(parts)] = path
    return mods


def _imports(name: str, path: Path, mods: dict[str, Path]) -> set[str]:
    """The project's modules ``name`` imports anywhere in its body, ``TYPE_CHECKING`` blocks left out."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    typing_only = {
        id(node)
        for block in ast.walk(tree)
        if isinstance(block, ast.If) and "TYPE_CHECKING" in ast.unparse(block.test)
        for node in ast.walk(block)
    }

    def known(target: str) -> str | None:
        while target and target not in mods:
            target = target.rpartition(".")[0]
        return target or None

    found = set()
    for node in ast.walk(tree):
        if id(node) in typing_only:
            continue
        if isinstance(node, ast.Import):
            found.update(known(alias.name) for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(up + ([node.module] if node.module else []))
            found.update(known(f"{base}.{alias.name}" if base else alias.name) for alias in node.names)
    return {m for m in found if m and m != name}


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected groups of more than one module (Tarjan)."""
    index, low, stack, on, groups = {}, {}, [], set(), []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = []
            while True:
                w = stack.pop()
                on.discard(w)
                group.append(w)
                if w == v:
                    break
            if len(group) > 1:
                groups.append(sorted(group))

    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10_000))
    for v in graph:
        if v not in index:
            visit(v)
    return groups


def test_no_import_cycles():
    mods = _modules()
    graph = {name: _imports(name, path, mods) for name, path in mods.items()}
    assert _cycles(graph) == []


def test_the_cycle_finder_finds_a_cycle():
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_no_core_function_is_longer_than_100_lines():
    long = []
    for path in sorted(ROOT.glob("core/**/*.py")):
        if path.name == "_kernels.py":  # the compiled pose kernels: straight-line arithmetic
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                lines = node.end_lineno - node.lineno + 1
                if lines > MAX_CORE_FUNCTION_LINES:
                    long.append(f"{path.relative_to(ROOT)}:{node.lineno} {node.name} ({lines} lines)")
    assert long == []


@pytest.mark.parametrize("args", [["check", "."], ["format", "--check", "."]], ids=["check", "format"])
def test_ruff(args):
    ruff = shutil.which("ruff") or str(Path(sys.executable).with_name("ruff"))
    if not Path(ruff).exists():
        pytest.skip("ruff is not installed (it comes with the test extras: pip install -e '.[test]')")
    done = subprocess.run([ruff, *args], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, (done.stdout + done.stderr)[-3000:]


MAX_PANEL_LINES = 450  # issue 24: the panel class
MAX_UPDATE_POSE_LINES = 500  # issue 24: Update pose with its app-side base classes


def _class_lines(path: Path) -> dict[str, tuple[int, list[str]]]:
    """Each top-level class of ``path``: (its lines, the names of its bases)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    return {
        n.name: (n.end_lineno - n.lineno + 1, [ast.unparse(b).rpartition(".")[2] for b in n.bases])
        for n in tree.body
        if isinstance(n, ast.ClassDef)
    }


def _app_classes() -> dict[str, tuple[int, list[str]]]:
    found: dict[str, tuple[int, list[str]]] = {}
    for path in sorted(ROOT.glob("app/**/*.py")):
        found.update(_class_lines(path))
    return found


def _with_bases(name: str, classes: dict) -> int:
    """Lines of class ``name`` and of every app-side class it derives from, each counted once."""
    seen, todo, total = set(), [name], 0
    while todo:
        c = todo.pop()
        if c in seen or c not in classes:
            continue
        seen.add(c)
        lines, bases = classes[c]
        total += lines
        todo += bases
    return total


def test_the_panel_is_short():
    lines = _class_lines(ROOT / "app/ui/client.py")["ClientPanel"][0]
    assert lines <= MAX_PANEL_LINES, f"ClientPanel is {lines} lines (at most {MAX_PANEL_LINES})"


def test_update_pose_with_its_bases_is_short():
    lines = _with_bases("UpdatePose", _app_classes())
    assert lines <= MAX_UPDATE_POSE_LINES, f"UpdatePose with its app-side bases is {lines} lines"


def test_the_panel_knows_no_workflow_by_name():
    """The panel sends intents and draws what it is given: no branch on a workflow's or step's name, no probe
    of a workflow's attributes."""
    said = []
    for path in sorted(ROOT.glob("app/ui/*.py")):
        for k, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            code = line.split("#", 1)[0]
            if any(s in code for s in ("wf.name", "getattr(wf", "hasattr(wf", "step.name ==", ".name in (")):
                said.append(f"{path.relative_to(ROOT)}:{k}: {line.strip()}")
    assert said == []
