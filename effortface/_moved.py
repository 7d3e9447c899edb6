"""Old import paths of moved modules keep working for one release, with a DeprecationWarning.

restructure: keep old names (``tools/restructure.py`` fills :data:`MOVED` and leaves this file's names alone)

``import effortface.train.energy`` (the old path) returns the very module object
``effortface.synth.energy`` is, so ``isinstance`` and monkeypatching see one module. The product
itself never uses an old path (``tests/test_layout.py`` checks the sources).
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.machinery
import sys
import warnings
from collections.abc import Sequence
from types import ModuleType

#: old dotted name -> new one; a moved package maps its submodules too (written by tools/restructure.py)
MOVED: dict[str, str] = {
    # BEGIN MOVED
    "effortface.capture_tool.hr_csv": "effortface.core.session.hr_csv",
    "effortface.capture_tool.session": "effortface.core.session.folder",
    "effortface.train.attach": "effortface.synth.attach",
    "effortface.train.batch_synth": "effortface.synth.batch_synth",
    "effortface.train.bundle": "effortface.synth.bundle",
    "effortface.train.catalog": "effortface.synth.catalog",
    "effortface.train.character_options": "effortface.synth.character_options",
    "effortface.train.commands.export_data": "effortface.interop.commands.export_data",
    "effortface.train.commands.import_data": "effortface.interop.commands.import_data",
    "effortface.train.commands.motion": "effortface.synth.commands.motion",
    "effortface.train.commands.serve": "effortface.interop.commands.serve",
    "effortface.train.commands.synth": "effortface.synth.commands.synth",
    "effortface.train.commands.work": "effortface.synth.commands.work",
    "effortface.train.curves_io": "effortface.synth.curves_io",
    "effortface.train.energy": "effortface.synth.energy",
    "effortface.train.exercise_log": "effortface.synth.exercise_log",
    "effortface.train.face": "effortface.synth.face",
    "effortface.train.gui.synth_stage": "effortface.synth.gui.synth_stage",
    "effortface.train.iir": "effortface.synth.iir",
    "effortface.train.interop": "effortface.interop",
    "effortface.train.interop.c3d_motion": "effortface.synth.c3d_motion",
    "effortface.train.motion": "effortface.synth.motion",
    "effortface.train.motion_csv": "effortface.synth.motion_csv",
    "effortface.train.npzio": "effortface.synth.npzio",
    "effortface.train.parallel": "effortface.synth.parallel",
    "effortface.train.physiology": "effortface.synth.physiology",
    "effortface.train.runtime": "effortface.synth.runtime",
    "effortface.train.segments": "effortface.synth.segments",
    "effortface.train.synth_session": "effortface.synth.synth_session",
    "effortface.train.work": "effortface.synth.work",
    # END MOVED
}


def new_name(old: str) -> str | None:
    """The current name of a module imported by its old name (``None`` if it did not move).

    Parameters
    ----------
    old : str
        A dotted module name, e.g. ``"effortface.train.energy"``.

    Returns
    -------
    str or None
        E.g. ``"effortface.synth.energy"``.
    """
    parts = old.split(".")
    for k in range(len(parts), 1, -1):
        prefix = ".".join(parts[:k])
        if prefix in MOVED:
            return MOVED[prefix] + old[len(prefix):]
    return None


class _AliasLoader(importlib.abc.Loader):
    """Loads an old name as the module object of its new name."""

    def __init__(self, new: str) -> None:
        self.new = new
        self.real_spec: importlib.machinery.ModuleSpec | None = None

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType:
        module = importlib.import_module(self.new)
        self.real_spec = module.__spec__
        return module

    def exec_module(self, module: ModuleType) -> None:
        # the import system stamped the old name's spec on the shared module object: give its own back
        module.__spec__ = self.real_spec


class _AliasFinder(importlib.abc.MetaPathFinder):
    """Finds old names (first on ``sys.meta_path``), warning once per name."""

    def find_spec(self, fullname: str, path: Sequence[str] | None = None,
                  target: ModuleType | None = None) -> importlib.machinery.ModuleSpec | None:
        new = new_name(fullname)
        if new is None:
            return None
        warnings.warn(f"{fullname} moved to {new}: import it from there (the old path goes in the next release)",
                      DeprecationWarning, stacklevel=2)
        return importlib.machinery.ModuleSpec(fullname, _AliasLoader(new))


def install() -> None:
    """Put the finder first on ``sys.meta_path`` (once)."""
    if MOVED and not any(isinstance(f, _AliasFinder) for f in sys.meta_path):
        sys.meta_path.insert(0, _AliasFinder())
