"""Imports point one way, as the README and the design draw it: the package's import graph — every import statement,
those inside functions included — never reaches from a layer to one above it (or across to another package of its
own layer). A failure names the importing module, the line and the import."""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "mrguide"

#: Each subpackage's layer, lowest first; the package's top-level modules (task, robot, config, ...) are layer 0
#: and `cli` is above everything. The order of the README: task/robot ◀ motion ◀ drivers ◀ deploy ◀ mujoco_cell ◀ twin ◀
#: policies ◀ annotation, experiments; calibration is used by deploy, twin and annotation; replay reads what
#: deploy, policies and annotation write.
LAYERS = {
    "motion": 1,
    "calibration": 1,
    "drivers": 2,
    "deploy": 3,
    "mujoco_cell": 4,
    "twin": 5,
    "policies": 6,
    "annotation": 7,
    "experiments": 8,
    "replay": 8,
    "cli": 9,
}


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
            if high > low or (high == low and source != "" and unit != ""):
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
