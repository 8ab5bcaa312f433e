"""Imports point one way, as the README and the design draw it: the package's import graph — every import statement,
those inside functions included — never reaches from a layer to one above it (or across to another package of its
own layer). A failure names the importing module, the line and the import."""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "mrguide"

#: Each subpackage's layer, lowest first; the package's top-level modules (task, robot, plant, config, ...) are layer 0
#: and `cli` is above everything. The order of the design: task/robot ◀ motion ◀ drivers ◀ deploy ◀ mujoco_cell ◀ twin ◀
#: cell ◀ policies ◀ annotation, experiments; calibration is used by deploy, twin and cell; replay reads what
#: deploy, policies and annotation write. `cell` (the dry-run harness) sits above both `deploy` and `twin` (the
#: training simulator), which never import each other.
LAYERS = {
    "motion": 1,
    "calibration": 1,
    "drivers": 2,
    "deploy": 3,
    "mujoco_cell": 4,
    "twin": 5,
    "cell": 6,
    "policies": 7,
    "annotation": 8,
    "experiments": 9,
    "replay": 9,
    "cli": 10,
}
#: (importer, imported) pairs that never meet although the layers would allow it: the training simulator trains on the
#: decision step (`motion.decision`), never on the deploy runtime.
APART = {("twin", "deploy")}


def _unit(module: str) -> str | None:
    """The layer unit a dotted module name belongs to: a subpackage, `cli`, or "" for the other top-level modules."""
    parts = module.split(".")
    if parts[0] != "mrguide":
        return None
    if len(parts) == 1:
        return ""
    return parts[1] if parts[1] in LAYERS else ""


def _imports(path: Path, root: Path) -> list[tuple[int, str]]:
    """(line, absolute module) of every import in `path` (a file under the package directory `root`), relative ones
    resolved, `from mrguide import x` as mrguide.x."""
    module = ".".join(path.relative_to(root.parent).with_suffix("").parts)
    package = module if path.name == "__init__.py" else module.rsplit(".", 1)[0]
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*anchor, base] if base else anchor)
            names = [f"{base}.{a.name}" for a in node.names] if base == "mrguide" else [base]
            found += [(node.lineno, name) for name in names]
    return found


def _violations(root: Path = PACKAGE) -> list[str]:
    problems = []
    for path in sorted(root.rglob("*.py")):
        if "node_modules" in path.parts:
            continue
        source = _unit(".".join(path.relative_to(root.parent).with_suffix("").parts))
        assert source is not None
        for line, target in _imports(path, root):
            unit = _unit(target)
            if unit is None or unit == source:
                continue
            low, high = LAYERS.get(source, 0), LAYERS.get(unit, 0)
            if high > low or (high == low and source != "" and unit != "") or (source, unit) in APART:
                problems.append(f"{path.relative_to(root.parent)}:{line}: {source or 'top level'} imports {target}")
    return problems


def test_imports_point_down_the_layers():
    assert _violations() == []


def test_the_check_sees_upward_imports_in_a_function_and_relative_ones(tmp_path):
    """An upward import hidden in a function body, or written relative, is found (every statement is walked)."""
    fake = tmp_path / "mrguide"
    (fake / "drivers").mkdir(parents=True)
    (fake / "drivers" / "x.py").write_text("def f():\n    from mrguide.twin import scene\n    return scene\n")
    (fake / "drivers" / "y.py").write_text("from ..policies import ddpg\nfrom . import x\n")
    assert _violations(fake) == [
        "mrguide/drivers/x.py:2: drivers imports mrguide.twin",
        "mrguide/drivers/y.py:1: drivers imports mrguide.policies",
    ]


def _module(path: Path, root: Path) -> str:
    return ".".join(path.relative_to(root.parent).with_suffix("").parts).removesuffix(".__init__")


def _imported_modules(path: Path, root: Path) -> set[str]:
    """What `path` imports, with `from package import name` also read as the module `package.name`."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            found |= {node.module} | {f"{node.module}.{a.name}" for a in node.names}
    return found | {name for _, name in _imports(path, root)}


def _circles(root: Path = PACKAGE) -> list[list[str]]:
    """The package's import circles between modules (function-local imports too), each as its sorted members."""
    paths = {_module(p, root): p for p in root.rglob("*.py") if "node_modules" not in p.parts}
    graph = {m: {t for t in _imported_modules(p, root) if t in paths and t != m} for m, p in paths.items()}

    def reach(start: str) -> set[str]:
        seen, todo = set(), [start]
        while todo:
            for nxt in graph[todo.pop()] - seen:
                seen.add(nxt)
                todo.append(nxt)
        return seen

    reached = {m: reach(m) for m in graph}
    return sorted({tuple(sorted({m} | {o for o in reached[m] if m in reached[o]})) for m in graph if m in reached[m]})


def test_no_import_circle():
    assert _circles() == []


def test_the_circle_check_and_the_apart_rule_see_what_they_forbid(tmp_path):
    fake = tmp_path / "mrguide"
    (fake / "cell").mkdir(parents=True)
    (fake / "twin").mkdir()
    (fake / "cell" / "a.py").write_text("def f():\n    from mrguide.cell import b\n")
    (fake / "cell" / "b.py").write_text("from mrguide.cell.a import f\n")
    (fake / "twin" / "env.py").write_text("from mrguide.deploy.runtime import Runtime\n")
    assert _circles(fake) == [("mrguide.cell.a", "mrguide.cell.b")]
    assert _violations(fake) == ["mrguide/twin/env.py:1: twin imports mrguide.deploy.runtime"]
