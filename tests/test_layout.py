"""The package's layout (docs/architecture.md): data flows down the floors, never up.

Read from the source with ``ast`` (every import statement, lazy imports inside functions
included), so the rules hold for every code path, not only the ones a test happens to run.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "bayes_fdi"

#: Floor of each top-level part of the package: a module imports only from its own part or from
#: parts on lower floors.
FLOORS: dict[str, int] = {
    # the foundation
    "atomic": 0,
    "memory": 0,
    "progress": 0,
    "cli_arguments": 1,
    "reporting": 1,
    "distributed": 2,
    # the library
    "datasets": 3,
    "actuator": 4,
    "rvm": 4,
    "model_files": 4,
    "campaigns": 5,
    "twin": 5,
    "diagnosis": 6,
    "calibration": 7,
    "scoring": 7,
    "default_diagnoser": 8,
    "commissioning": 8,
    # the applications, then the command line
    "paper": 9,
    "benchmark": 9,
    "deployment": 9,
    "commands": 10,
    "cli": 10,
    "__main__": 11,
}
FOUNDATION = ("atomic", "memory", "progress", "cli_arguments", "reporting", "distributed")
#: The concepts of `bayes_fdi.diagnosis`, in the order they may import one another.
DIAGNOSIS_FLOORS: dict[str, int] = {
    "component_state": 0,
    "normal_models": 0,
    "detection": 1,
    "isolation": 2,
    "seva": 3,
    "fault_diagnoser": 4,
    "online": 4,
}
APPLICATIONS = ("paper", "benchmark", "deployment")


def _modules() -> list[tuple[str, Path]]:
    out = []
    for path in sorted(PACKAGE.rglob("*.py")):
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out.append((".".join(parts), path))
    return out


def _imports(name: str, path: Path) -> list[tuple[str, str, int]]:
    """(imported module, imported name or '', line) of every bayes_fdi import in a module."""
    tree = ast.parse(path.read_text(), filename=str(path))
    is_package = path.name == "__init__.py"
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(a.name, "", node.lineno) for a in node.names if a.name.startswith("bayes_fdi")]
        elif isinstance(node, ast.ImportFrom):
            module = node.module or ""
            if node.level:
                base = name.split(".") if is_package else name.split(".")[:-1]
                base = base[: len(base) - node.level + 1]
                module = ".".join([*base, module] if module else base)
            if module.startswith("bayes_fdi"):
                out += [(module, a.name, node.lineno) for a in node.names]
    return out


def _part(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


MODULES = _modules()


def test_every_part_of_the_package_has_a_floor():
    parts = {_part(m) for m, _ in MODULES} - {""}
    assert parts <= set(FLOORS), sorted(parts - set(FLOORS))


def _violations(rule) -> list[str]:
    out = []
    for module, path in MODULES:
        for target, name, line in _imports(module, path):
            full = f"{target}.{name}" if name else target
            problem = rule(module, target, full)
            if problem:
                out.append(f"{path.relative_to(PACKAGE.parent)}:{line} imports {full}: {problem}")
    return out


def _floor_rule(module: str, target: str, full: str) -> str | None:
    here, there = _part(module), _part(target)
    if not here or not there or here == there:
        return None
    if FLOORS[there] > FLOORS[here]:
        return f"{there} (floor {FLOORS[there]}) is above {here} (floor {FLOORS[here]})"
    if FLOORS[there] == FLOORS[here]:
        return f"{here} and {there} are siblings on floor {FLOORS[here]}"
    return None


def test_imports_flow_down_the_floors_and_applications_do_not_import_one_another():
    assert _violations(_floor_rule) == []


def _diagnosis_rule(module: str, target: str, full: str) -> str | None:
    if _part(module) != "diagnosis" or _part(target) != "diagnosis":
        return None
    here = module.split(".")[2:3]
    there = full.split(".")[2:3]
    if not here or not there or here == there or there[0] not in DIAGNOSIS_FLOORS:
        return None
    a, b = DIAGNOSIS_FLOORS.get(here[0]), DIAGNOSIS_FLOORS[there[0]]
    if a is not None and b > a:
        return f"diagnosis concept {there[0]} is above {here[0]}"
    return None


def test_the_concepts_of_diagnosis_import_only_those_below_them():
    assert _violations(_diagnosis_rule) == []


def _private_rule(module: str, target: str, full: str) -> str | None:
    name = full.rsplit(".", 1)[-1]
    if name.startswith("_") and not name.startswith("__") and target != module:
        return "a private name of another module"
    return None


def test_no_private_name_is_imported_from_another_module():
    assert _violations(_private_rule) == []


def test_rvm_knows_nothing_of_actuators():
    rvm = [(m, p) for m, p in MODULES if _part(m) == "rvm"]
    bad = [
        f"{m} imports {t}"
        for m, p in rvm
        for t, _, _ in _imports(m, p)
        if _part(t) not in ("", "rvm", *FOUNDATION)
    ]
    assert bad == []


@pytest.mark.parametrize("module, path", MODULES, ids=[m for m, _ in MODULES])
def test_modules_stay_small(module, path):
    """One module a concept, under about 500 lines."""
    assert len(path.read_text().splitlines()) <= 520


def test_no_module_defines_a_top_level_function_or_class_twice():
    """A second definition silently replaces the first (ruff does not flag it where nothing
    uses the first in between): every module-level ``def`` and ``class`` name appears once."""
    bad = []
    for module, path in MODULES:
        seen: dict[str, int] = {}
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
                if node.name in seen:
                    bad.append(f"{module}: {node.name} (lines {seen[node.name]}, {node.lineno})")
                seen.setdefault(node.name, node.lineno)
    assert bad == []
