"""The architecture rules of DESIGN.md, enforced (napari/MNE style).

- Qt (PySide6, pyqtgraph) only in ``*/gui/`` and ``effortface/app.py``.
- Data flows one way: capture_tool <- annotate <- train <- effortface.
- ``train/runtime.py`` and everything it imports use numpy and scipy only.
"""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ["capture_tool", "annotate", "train", "effortface"]
QT = {"PySide6", "pyqtgraph", "shiboken6", "PyQt5", "PyQt6"}
UPSTREAM = {"capture_tool": set(), "annotate": {"capture_tool"},
            "train": {"capture_tool", "annotate"}, "effortface": set(PACKAGES)}


def _imports(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(a.name.split(".")[0] for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module.split(".")[0])
    return names


def _sources() -> list[Path]:
    return [p for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py")]


@pytest.mark.parametrize("path", _sources(), ids=lambda p: str(p.relative_to(ROOT)))
def test_qt_only_in_gui(path: Path) -> None:
    rel = path.relative_to(ROOT)
    if "gui" in rel.parts or rel.as_posix() == "effortface/app.py":
        return
    assert not (_imports(path) & QT), f"{rel} imports Qt outside gui/"


@pytest.mark.parametrize("path", _sources(), ids=lambda p: str(p.relative_to(ROOT)))
def test_imports_flow_one_way(path: Path) -> None:
    rel = path.relative_to(ROOT)
    pkg = rel.parts[0]
    allowed = UPSTREAM[pkg] | {pkg}
    bad = (_imports(path) & set(PACKAGES)) - allowed
    assert not bad, f"{rel} imports downstream package(s) {sorted(bad)}"


def _new_top_modules(statement: str) -> set[str]:
    """Top-level modules that ``statement`` adds to ``sys.modules`` in a fresh interpreter."""
    code = (
        "import sys, json; before = set(sys.modules);"
        f"{statement};"
        "print(json.dumps(sorted({m.split('.')[0] for m in set(sys.modules) - before})))"
    )
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True,
                         check=True)
    return set(json.loads(out.stdout.strip().splitlines()[-1]))


def test_runtime_imports_numpy_scipy_only() -> None:
    """What ``import train.runtime`` brings in is numpy, scipy (and what they drag), our own code."""
    if not (ROOT / "train" / "runtime.py").exists():
        pytest.skip("train/runtime.py not written yet")
    # scipy.signal pulls a few helpers of its own (numpy.f2py's charset_normalizer...): allowed.
    baseline = _new_top_modules("import numpy, scipy, scipy.signal, scipy.interpolate")
    new = _new_top_modules("import train.runtime") - baseline
    third_party = {m for m in new if m not in sys.stdlib_module_names and not m.startswith("_")}
    assert third_party <= {"numpy", "scipy", *PACKAGES}, sorted(third_party)
    assert not (new & {"sklearn", "pandas", "cv2", "PySide6", "pyqtgraph", "onnx", "onnxruntime"})


def test_import_linter_contracts() -> None:
    """import-linter checks the layer contract in pyproject.toml (indirect imports included)."""
    lint = subprocess.run(["lint-imports", "--no-cache"], cwd=ROOT, capture_output=True, text=True)
    assert lint.returncode == 0, lint.stdout + lint.stderr
