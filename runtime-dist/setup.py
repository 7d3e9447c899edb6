"""Build ``effortface-runtime``: the effortface package tree restricted to the public runtime.

The modules are not listed by hand: :func:`runtime_modules` follows the ``import`` statements
(function-level ones included) from ``effortface.runtime`` through the repository's sources, so a
module the runtime starts to use ships without anyone editing this file. The folders are the main
distribution's (``../effortface``, and ``../train`` for ``effortface.train``); metadata is in
``pyproject.toml``.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

ROOT = Path(__file__).resolve().parent.parent
#: the packages the runtime may use -> their folders, relative to this file
PACKAGE_DIR = {"effortface": "../effortface", "effortface.core": "../effortface/core",
               "effortface.synth": "../effortface/synth"}

ENTRY = "effortface.runtime"


def _source(module: str) -> Path | None:
    """The file of ``module`` (a module or a package's ``__init__.py``), or None if there is none."""
    package, _, name = module.rpartition(".")
    if module in PACKAGE_DIR:
        return ROOT / PACKAGE_DIR[module][3:] / "__init__.py"
    if package in PACKAGE_DIR:
        path = ROOT / PACKAGE_DIR[package][3:] / f"{name}.py"
        return path if path.is_file() else None
    return None


def _imported(path: Path) -> set[str]:
    """The effortface modules ``path`` imports (``from a import b`` counts ``a.b`` if it is a module)."""
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
            names.update(f"{node.module}.{a.name}" for a in node.names if _source(f"{node.module}.{a.name}"))
    return {n for n in names if n == "effortface" or n.startswith("effortface.")}


def runtime_modules() -> set[str]:
    """``effortface.runtime`` and every effortface module it imports, directly or not, with their packages.

    Raises
    ------
    RuntimeError
        If the runtime imports an effortface module outside :data:`PACKAGE_DIR` (e.g. a stage that
        needs Qt or OpenCV).
    """
    todo, done = [ENTRY], set()
    while todo:
        module = todo.pop()
        if module in done:
            continue
        path = _source(module)
        if path is None:
            raise RuntimeError(f"{module}: imported by the runtime, but not in {sorted(PACKAGE_DIR)}")
        done.add(module)
        parents = [module.rsplit(".", k)[0] for k in range(1, module.count(".") + 1)]
        todo += parents + sorted(_imported(path))
    return done


class RuntimeOnlyBuild(build_py):
    """``build_py`` that copies only the runtime's modules of each package."""

    def find_package_modules(self, package: str, package_dir: str) -> list[tuple[str, str, str]]:
        keep = runtime_modules()
        return [(pkg, mod, path) for pkg, mod, path in super().find_package_modules(package, package_dir)
                if (pkg if mod == "__init__" else f"{pkg}.{mod}") in keep]


def _version() -> str:
    """The one version string, read from ``effortface/core/version.py`` (not imported: nothing is installed yet)."""
    path = ROOT / "effortface" / "core" / "version.py"
    found = re.search(r'^__version__ = "([^"]+)"', path.read_text(encoding="utf-8"), re.M)
    if found is None:
        raise RuntimeError(f"{path}: expected a line __version__ = \"...\", found none")
    return found.group(1)


setup(
    version=_version(),
    packages=list(PACKAGE_DIR),
    package_dir=PACKAGE_DIR,
    package_data={"effortface.synth": ["data/*.csv"]},
    cmdclass={"build_py": RuntimeOnlyBuild},
)
