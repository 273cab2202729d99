"""The API reference renders the docstrings as the site shows them: no raw reST, each name once.

The fast tests run the documentation's own build code (the ``docs/hooks`` griffe extension and
MkDocs hook) on the package, as ``mkdocs build`` does, and check what it produces against the
package imported by Python; the slow one builds the site (without the notebooks) and reads the
HTML.
"""

from __future__ import annotations

import importlib
import importlib.util
import inspect
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

griffe = pytest.importorskip("griffe")
pytest.importorskip("mkdocs")
yaml = pytest.importorskip("yaml")

ROOT = Path(__file__).resolve().parents[1]
HOOKS = ROOT / "docs" / "hooks"

# what Markdown would show literally: reST roles, Sphinx's default role, directives
RAW_REST = re.compile(r":(?:py:)?[a-z]+:`|(?<!`)`~[A-Za-z_]|^\s*\.\. [a-z]+::", re.M)


def _hook(name: str):
    spec = importlib.util.spec_from_file_location(f"docs_hook_{name}", HOOKS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def roles():
    return _hook("griffe_roles")


@pytest.fixture(scope="module")
def api_pages():
    return _hook("api_pages")


@pytest.fixture(scope="module")
def loaded(roles):
    """The package as mkdocstrings loads it, with the extension that mkdocs.yml enables."""
    loader = griffe.GriffeLoader(
        extensions=griffe.load_extensions(roles.ReSTRoles), docstring_parser=griffe.Parser.numpy
    )
    package = loader.load("bayes_fdi")
    loader.resolve_aliases(implicit=False, external=False)
    return loader, package


def test_convert_hand_written_cases(roles):
    def public(target, obj):
        return {"bayes_fdi.rvm.regression.RVR": "bayes_fdi.rvm.RVR"}.get(target)

    cases = {
        ":class:`~bayes_fdi.rvm.regression.RVR`": "[`RVR`][bayes_fdi.rvm.RVR]",
        ":class:`bayes_fdi.rvm.regression.RVR`": "[`bayes_fdi.rvm.RVR`][bayes_fdi.rvm.RVR]",
        ":func:`~bayes_fdi.x.helper`": "`helper`",
        ":mod:`bayes_fdi.rvm.sbl`": "`bayes_fdi.rvm.sbl`",
        ":class:`the estimator <bayes_fdi.rvm.regression.RVR>`": (
            "[`the estimator`][bayes_fdi.rvm.RVR]"
        ),
        "see `~bayes_fdi.rvm.regression.RVR`.": "see [`RVR`][bayes_fdi.rvm.RVR].",
        "``~literal`` stays": "``~literal`` stays",
        r"gain :math:`\alpha_i^{-1}` here": r"gain $\alpha_i^{-1}$ here",
        "Model:\n\n.. math::\n\n    a = b\n    + c\n\nafter": (
            "Model:\n\n$$\na = b\n+ c\n$$\n\nafter"
        ),
    }
    for text, expected in cases.items():
        assert roles.convert(text, None, public) == expected, text


def test_no_raw_rest_left_in_any_docstring(loaded, roles):
    _, package = loaded
    left = []
    for obj in roles._objects(package):
        if obj.docstring is not None:
            left += [f"{obj.path}: {m.group(0)!r}" for m in RAW_REST.finditer(obj.docstring.value)]
    assert not left, "\n".join(left[:20])


def test_every_formula_renders_to_mathml(loaded, roles):
    from latex2mathml.converter import convert as to_mathml

    _, package = loaded
    formulas = []
    for obj in roles._objects(package):
        if obj.docstring is None:
            continue
        text = obj.docstring.value
        formulas += re.findall(r"\$\$\n(.*?)\n\s*\$\$", text, re.S)
        formulas += re.findall(
            r"(?<![$\\])\$([^$\n]+)\$(?!\$)", re.sub(r"\$\$.*?\$\$", "", text, flags=re.S)
        )
    assert len(formulas) >= 20  # the RVM's and the posteriors' docstrings hold about 25
    for formula in formulas:
        assert "<math" in to_mathml(formula.strip()), formula


def test_links_point_at_documented_entries(loaded, roles):
    loader, package = loaded
    documented = set(roles.documented_paths(loader).values())
    links = []
    for obj in roles._objects(package):
        if obj.docstring is not None:
            links += re.findall(r"\]\[([\w.]+)\]", obj.docstring.value)
    assert len(links) > 100
    assert set(links) <= documented


def test_each_public_object_rendered_once(api_pages):
    faces = api_pages.public_faces()
    assert "bayes_fdi.rvm.sbl" not in faces  # internal numerics: no page
    assert {"bayes_fdi.actuator", "bayes_fdi.diagnosis", "bayes_fdi.diagnosis.online"} <= set(faces)
    pages_of: dict[int, list[str]] = {}  # object -> the pages that render it
    for package, face in faces.items():
        module = importlib.import_module(package)
        assert sorted(face.names) == sorted(module.__all__)
        own, elsewhere = api_pages.page_names(package, faces)
        parent = api_pages.parent_face(package, faces)
        for name in elsewhere:  # left to the parent's page: the very same object
            assert getattr(importlib.import_module(parent), name) is getattr(module, name)
        for name in own:
            path = api_pages.render_path(package, name, face)
            owner, _, attr = path.rpartition(".")
            obj = getattr(importlib.import_module(owner), attr)
            assert obj is getattr(module, name), path
            if inspect.isclass(obj) or inspect.isfunction(obj):
                pages_of.setdefault(id(obj), []).append(package)
    nested = [
        pages
        for pages in pages_of.values()
        if any(a != b and a.startswith(b + ".") for a in pages for b in pages)
    ]
    assert not nested, nested


def test_shadowed_names_are_rendered_from_their_module(api_pages):
    faces = api_pages.public_faces()
    # functions named like the submodule that defines them
    assert (
        api_pages.render_path("bayes_fdi.actuator", "simulate", faces["bayes_fdi.actuator"])
        == "bayes_fdi.actuator.simulate.simulate"
    )
    assert (
        api_pages.render_path("bayes_fdi.scoring", "picalc", faces["bayes_fdi.scoring"])
        == "bayes_fdi.scoring.picalc.picalc"
    )
    assert api_pages.render_path("bayes_fdi.actuator", "Fault", faces["bayes_fdi.actuator"]) == (
        "bayes_fdi.actuator.Fault"
    )


def _site_config(tmp_path: Path) -> Path:
    """mkdocs.yml without the notebooks (they are built by ``make notebooks``), paths absolute."""
    config = yaml.safe_load((ROOT / "mkdocs.yml").read_text())
    config["docs_dir"] = str(tmp_path / "docs")
    config["hooks"] = [str(ROOT / hook) for hook in config["hooks"]]
    config["plugins"] = [
        p for p in config["plugins"] if not (isinstance(p, dict) and "mkdocs-jupyter" in p)
    ]
    for plugin in config["plugins"]:
        if isinstance(plugin, dict) and "mkdocstrings" in plugin:
            python = plugin["mkdocstrings"]["handlers"]["python"]
            python["paths"] = [str(ROOT)]
            python["options"]["extensions"] = [
                str(ROOT / e) if isinstance(e, str) and e.endswith(".py") else e
                for e in python["options"].get("extensions", [])
            ]
    config["nav"] = [item for item in config["nav"] if "Notebooks" not in item]
    shutil.copytree(
        ROOT / "docs", tmp_path / "docs", ignore=shutil.ignore_patterns("notebooks", "hooks")
    )
    path = tmp_path / "mkdocs.yml"
    path.write_text(yaml.safe_dump(config, sort_keys=False))
    return path


@pytest.mark.slow
def test_strict_site_build_shows_no_raw_markup(tmp_path):
    config = _site_config(tmp_path)
    site = tmp_path / "site"
    result = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-f", str(config), "-d", str(site)],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT), "NO_MKDOCS_2_WARNING": "1"},
    )
    assert result.returncode == 0, result.stderr[-3000:]
    pages = sorted((site / "api").glob("*/index.html"))
    assert len(pages) >= 10
    raw = re.compile(r":(?:math|class|func|meth|mod|data|attr|exc|obj):`|~bayes_fdi|\\frac|\\alpha")
    for page in pages + sorted(site.glob("*/index.html")):
        text = page.read_text()
        assert not raw.findall(text), (page, raw.findall(text)[:5])
    actuator = (site / "api" / "bayes_fdi.actuator" / "index.html").read_text()
    assert 'id="bayes_fdi.actuator.simulate.simulate"' in actuator
    rvm = (site / "api" / "bayes_fdi.rvm" / "index.html").read_text()
    assert 'id="bayes_fdi.rvm.RVR.fit_posterior"' in rvm  # inherited from the RVM base
    assert "<math" in rvm
    online = (site / "api" / "bayes_fdi.diagnosis.online" / "index.html").read_text()
    assert 'id="bayes_fdi.diagnosis.online.OnlineDiagnoser"' not in online
