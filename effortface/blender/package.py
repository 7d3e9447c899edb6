"""The installable zip of the Blender add-on (``effortface blender-addon --out FILE.zip``).

Layout (a Blender 4.2+ extension; Blender installs it with *Install from Disk* or
``bpy.ops.extensions.package_install_files``)::

    blender_manifest.toml      version = this package's
    __init__.py, bake.py, ui.py
    LICENSE
    vendor/effortface/...      the numpy runtime: RUNTIME_MODULES and their data tables

:data:`RUNTIME_MODULES` are exactly the modules that importing ``effortface.runtime`` and
``effortface.synth.curves_io`` loads in a fresh interpreter (``tests/blender/test_addon_zip.py``
checks it): numpy only, no scipy (Blender's Python ships numpy, not scipy), no Qt, pandas or
scikit-learn. Nothing else of effortface is bundled.
"""

from __future__ import annotations

import io
import re
import zipfile
from pathlib import Path

from effortface.core.errors import UserError
from effortface.core.fileio import atomic_write
from effortface.core.version import __version__

#: the package root (``effortface/``)
PACKAGE = Path(__file__).resolve().parent.parent
#: this folder: the add-on's own files go to the zip's root
ADDON = Path(__file__).resolve().parent
ADDON_FILES = ("blender_manifest.toml", "__init__.py", "bake.py", "ui.py")
#: the runtime's modules (dotted names), bundled under ``vendor/``
RUNTIME_MODULES = (
    "effortface", "effortface._moved",
    "effortface.core", "effortface.core.blendshapes", "effortface.core.bounds", "effortface.core.errors",
    "effortface.core.fileio", "effortface.core.participant", "effortface.core.stops", "effortface.core.version",
    "effortface.runtime",
    "effortface.synth", "effortface.synth.bundle", "effortface.synth.curves_io", "effortface.synth.energy",
    "effortface.synth.face", "effortface.synth.iir", "effortface.synth.motion", "effortface.synth.npzio",
    "effortface.synth.physiology", "effortface.synth.runtime", "effortface.synth.segments",
)
#: data files the runtime reads (the resting-HR chart, the de Leva tables), relative to the package
RUNTIME_DATA = ("synth/data/resting_hr_chart.csv", "synth/data/segment_inertia_tables.csv")


def module_file(name: str) -> Path:
    """The source file of a dotted module name of :data:`RUNTIME_MODULES`."""
    rel = Path(*name.split(".")[1:])
    folder = PACKAGE / rel
    return folder / "__init__.py" if folder.is_dir() else PACKAGE / rel.with_suffix(".py")


def manifest_text() -> str:
    """``blender_manifest.toml`` with this package's version."""
    text = (ADDON / "blender_manifest.toml").read_text(encoding="utf-8")
    return re.sub(r'(?m)^version = ".*"$', f'version = "{__version__}"', text, count=1)


def zip_entries() -> dict[str, bytes]:
    """Zip path -> content of every file of the add-on."""
    entries = {"blender_manifest.toml": manifest_text().encode("utf-8"),
               "LICENSE": (PACKAGE.parent / "LICENSE").read_bytes() if (PACKAGE.parent / "LICENSE").is_file()
               else b"MIT License (see https://opensource.org/license/mit)\n"}
    for name in ADDON_FILES[1:]:
        entries[name] = (ADDON / name).read_bytes()
    for module in RUNTIME_MODULES:
        src = module_file(module)
        entries[f"vendor/effortface/{src.relative_to(PACKAGE).as_posix()}"] = src.read_bytes()
    for rel in RUNTIME_DATA:
        entries[f"vendor/effortface/{rel}"] = (PACKAGE / rel).read_bytes()
    return entries


def build_zip(out: str | Path, force: bool = False) -> tuple[Path, int]:
    """Write the add-on zip to ``out``; (path, number of files).

    Raises
    ------
    UserError
        ``--out`` is a folder, exists (without ``force``), is not a ``.zip`` or sits in no folder.
    """
    path = Path(out)
    if path.is_dir():
        raise UserError(f"--out {path}: expected a .zip file path, found a folder")
    if path.suffix.lower() != ".zip":
        raise UserError(f"--out {path}: expected a file name ending in .zip, found {path.suffix or 'none'}")
    if path.exists() and not force:
        raise UserError(f"--out {path}: expected a new file, found an existing one (use --force to replace it)")
    if not path.parent.is_dir():
        raise UserError(f"--out {path}: expected an existing folder, found no {path.parent}")
    entries = zip_entries()
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
        for name, data in entries.items():
            z.writestr(name, data)
    atomic_write(path, lambda f: f.write(buf.getvalue()))
    return path, len(entries)
