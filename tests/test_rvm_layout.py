"""The layout of the RVM solver family (``bayes_fdi.rvm.sbl``): one public face, layered modules.

Read from the source with ``ast`` (every import statement, lazy ones inside functions included):

* outside ``bayes_fdi/rvm/sbl/`` the package imports the family only through its face,
  ``bayes_fdi.rvm.sbl``, and only names the face exports; tests and benchmarks too, except a
  module imported whole (``import bayes_fdi.rvm.sbl.gaussian as gaussian_module``) to patch one
  of its constants or count its calls;
* inside, each module imports only modules on a lower layer (the order the face's docstring
  gives), so there is no import circle.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import bayes_fdi.rvm.sbl as sbl

ROOT = Path(__file__).resolve().parents[1]
FACE = "bayes_fdi.rvm.sbl"
#: Layer of each module of the family: a module imports only from lower layers.
LAYERS: dict[str, int] = {
    "screening_copy": 0,
    "action_kernels": 0,
    "factor_kernels": 0,
    "tracked_kernels": 0,
    "design": 1,
    "precision_factor": 0,
    "rounding": 0,
    "noise": 0,
    "capacity": 0,
    "result": 2,
    "decisions": 0,
    "residual_factors": 1,
    "screening": 1,
    "verification": 1,
    "alignment": 2,
    "posterior_bounds": 1,
    "tracked_compiled": 2,
    "tracked_factors": 3,
    "laplace": 1,
    "gaussian": 4,
    "bernoulli": 3,
    "reestimation": 3,
    "polish": 5,
}


def _imports(path: Path) -> list[tuple[str, list[str], bool, int]]:
    """(module, imported names, whether an ``import x`` statement, line) of each import."""
    tree = ast.parse(path.read_text(), filename=str(path))
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out += [(a.name, [], True, node.lineno) for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            out.append((node.module, [a.name for a in node.names], False, node.lineno))
    return out


def _files(*folders: str) -> list[Path]:
    """The project's Python files under ``folders``, not those of a hidden folder such as the
    peers' environment that ``benchmarks/rvm_fit.py`` creates in ``benchmarks/.venv-peers``."""
    return sorted(
        p
        for folder in folders
        for p in (ROOT / folder).rglob("*.py")
        if not any(part.startswith(".") for part in p.relative_to(ROOT).parts)
    )


def test_every_module_of_the_family_has_a_layer():
    modules = {p.stem for p in (ROOT / "bayes_fdi/rvm/sbl").glob("*.py")} - {"__init__"}
    assert modules == set(LAYERS)


def test_outside_the_family_only_its_face_is_imported():
    bad = []
    for path in _files("bayes_fdi", "tests", "benchmarks"):
        inside = path.is_relative_to(ROOT / "bayes_fdi/rvm/sbl")
        package = path.is_relative_to(ROOT / "bayes_fdi")
        for module, names, plain, line in _imports(path):
            if inside or not module.startswith(FACE):
                continue
            where = f"{path.relative_to(ROOT)}:{line}"
            if module == FACE:
                bad += [f"{where} imports {n}, not exported" for n in names if n not in sbl.__all__]
            elif package or not plain:
                bad.append(f"{where} imports {module}")
    assert bad == []


@pytest.mark.parametrize("module", sorted(LAYERS))
def test_the_family_imports_only_lower_layers(module):
    path = ROOT / "bayes_fdi/rvm/sbl" / f"{module}.py"
    above = []
    for target, _, _, line in _imports(path):
        if target.startswith(FACE + "."):
            there = target.removeprefix(FACE + ".")
            if LAYERS[there] >= LAYERS[module]:
                above.append(f"line {line}: {there} (layer {LAYERS[there]})")
        elif target == FACE:
            above.append(f"line {line}: the face itself")
    assert above == []
