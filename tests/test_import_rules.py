"""The architecture rules of DESIGN.md, enforced (napari/MNE style).

- One installed namespace: everything is ``effortface.*``; no code imports a top-level
  ``capture_tool``, ``annotate`` or ``train`` (a PyPI package or a user's ``train.py`` could shadow it).
- Layers: core <- capture_tool <- annotate <- train <- front door (cli, app, commands, runtime).
- Qt (PySide6, pyqtgraph) only in ``gui/`` folders and ``effortface/app.py``; no other module imports a
  ``gui`` module.
- ``effortface.runtime`` and everything it imports use numpy and scipy only.
- Command modules (``*/commands/*.py``) only parse arguments, call library functions and print:
  nothing but ``effortface/cli.py`` imports one (not the library, the GUI, another command,
  the benchmarks or the sample-lab script), so their work is always reachable as a library function.
"""

from __future__ import annotations

import ast
import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import ROOT, module_name, product_sources

#: the layers, lowest first: a module may import its own layer and those before it
LAYERS = ["effortface.core", "effortface.capture_tool", "effortface.annotate", "effortface.synth", "effortface.train",
          "effortface.interop", "effortface"]
QT = {"PySide6", "pyqtgraph", "shiboken6", "PyQt5", "PyQt6"}
OLD_TOP_LEVEL = {"capture_tool", "annotate", "train"}
#: a command module: effortface.commands.X or effortface.<stage>.commands.X (or the package itself)
COMMAND_MODULE = re.compile(r"^effortface(\.(capture_tool|annotate|synth|train|interop))?\.commands(\.|$)")


def _imports(path: Path) -> set[str]:
    """Every absolute module name imported anywhere in ``path`` (function-level imports included)."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
            names.update(f"{node.module}.{a.name}" for a in node.names)
    return names


def _layer_of(path: Path) -> str:
    return LAYERS[_layer_index(module_name(path)) or 0]


def _sources() -> list[Path]:
    """Source files, each once (in either layout: tests/conftest.py)."""
    return product_sources()


def _layer_index(module: str) -> int | None:
    for i, layer in enumerate(LAYERS):
        if module == layer or module.startswith(layer + "."):
            return i
    return None


@pytest.mark.parametrize("path", _sources(), ids=lambda p: str(p.relative_to(ROOT)))
def test_qt_only_in_gui(path: Path) -> None:
    rel = path.relative_to(ROOT)
    if "gui" in rel.parts or rel.as_posix() == "effortface/app.py":
        return
    names = _imports(path)
    assert not {n.split(".")[0] for n in names} & QT, f"{rel} imports Qt outside gui/"
    gui = sorted(n for n in names if n.startswith("effortface.") and ".gui" in n and n != "effortface.app")
    assert rel.parts[0] == "effortface" and rel.parts[1] in ("commands",) or not gui, \
        f"{rel} imports GUI module(s) {gui} outside gui/"


@pytest.mark.parametrize("path", _sources(), ids=lambda p: str(p.relative_to(ROOT)))
def test_imports_flow_one_way(path: Path) -> None:
    rel = path.relative_to(ROOT)
    own = LAYERS.index(_layer_of(path))
    names = _imports(path)
    old = sorted(n for n in names if n.split(".")[0] in OLD_TOP_LEVEL)
    assert not old, f"{rel} imports the old top-level module(s) {old}: use effortface.*"
    bad = sorted(n for n in names if (i := _layer_index(n)) is not None and i > own)
    assert not bad, f"{rel} ({LAYERS[own]}) imports downstream module(s) {bad}"


def _new_top_modules(statement: str, cwd: Path) -> set[str]:
    """Top-level modules that ``statement`` adds to ``sys.modules`` in a fresh interpreter."""
    code = (
        "import sys, json; before = set(sys.modules);"
        f"{statement};"
        "print(json.dumps(sorted({m.split('.')[0] for m in set(sys.modules) - before})))"
    )
    out = subprocess.run([sys.executable, "-c", code], cwd=cwd, capture_output=True, text=True,
                         check=True)
    return set(json.loads(out.stdout.strip().splitlines()[-1]))


def test_runtime_imports_numpy_scipy_only(tmp_path: Path) -> None:
    """``import effortface.runtime`` in a fresh interpreter, from a folder holding a user's own
    ``train.py`` and ``annotate.py``, brings in numpy, scipy (and what they drag) and our own code."""
    (tmp_path / "train.py").write_text("raise SystemExit('the user train.py was imported')\n")
    (tmp_path / "annotate.py").write_text("raise SystemExit('the user annotate.py was imported')\n")
    # scipy.signal pulls a few helpers of its own (numpy.f2py's charset_normalizer...): allowed.
    baseline = _new_top_modules("import numpy, scipy, scipy.signal, scipy.interpolate", tmp_path)
    new = _new_top_modules("from effortface.runtime import load_model, Character, read_motion, "
                           "motion_from_positions; load_model('default')", tmp_path) - baseline
    third_party = {m for m in new if m not in sys.stdlib_module_names and not m.startswith("_")}
    assert third_party <= {"numpy", "scipy", "effortface"}, sorted(third_party)
    assert not (new & {"sklearn", "pandas", "cv2", "PySide6", "pyqtgraph", "onnx", "onnxruntime"})


def test_import_linter_contracts() -> None:
    """import-linter checks the layer and runtime contracts in pyproject.toml (indirect imports too)."""
    lint = subprocess.run([sys.executable, "-c", "import sys; from importlinter.cli import lint_imports_command; "
                          "sys.exit(lint_imports_command())", "--no-cache"], cwd=ROOT, capture_output=True, text=True)
    assert lint.returncode == 0, lint.stdout + lint.stderr


def _command_modules_imported(path: Path) -> list[str]:
    """The command modules (or packages) that ``path`` imports."""
    return sorted(n for n in _imports(path) if COMMAND_MODULE.match(n))


def _module_name(path: Path) -> str:
    """The dotted module name of a source file."""
    return module_name(path)


@pytest.mark.parametrize("path", _sources() + sorted((ROOT / "benchmarks").glob("*.py"))
                         + sorted((ROOT / "sample_sessions").glob("*.py")),
                         ids=lambda p: str(p.relative_to(ROOT)))
def test_only_the_cli_imports_command_modules(path: Path) -> None:
    rel = path.relative_to(ROOT)
    if rel.as_posix() == "effortface/cli.py":
        return
    found = _command_modules_imported(path)
    if "commands" in rel.parts:  # a command module may name its own package, never another command
        own = _module_name(path)
        found = [n for n in found if not (n == own or own.startswith(n + ".") or n.startswith(own + "."))]
    assert not found, (f"{rel} imports the command module(s) {found}: move the code it needs into a "
                       "library module, which the command then calls")


def test_the_command_module_rule_catches_an_import(tmp_path: Path) -> None:
    """The rule above sees both import forms and lets a module name its own package."""
    lib = tmp_path / "lib.py"
    lib.write_text("from effortface.synth.commands.synth import run\n"
                   "def f():\n    import effortface.commands.demo\n")
    assert _command_modules_imported(lib) == ["effortface.commands.demo", "effortface.synth.commands.synth",
                                              "effortface.synth.commands.synth.run"]
    assert _module_name(ROOT / "train" / "commands" / "train.py") == "effortface.train.commands.train"
    assert _module_name(ROOT / "effortface" / "train" / "commands" / "train.py") == "effortface.train.commands.train"
    assert _module_name(ROOT / "effortface" / "commands" / "__init__.py") == "effortface.commands"
