"""The blendshape set: names, key-framing order and ARKit export mapping (project configuration).

SCIENCE.md section 5: four blendshapes (mouth, eyes, eyebrows). The set is configuration, not
hard-coded: every stage takes a :class:`BlendshapeSet`, and :data:`DEFAULT_SET` is the paper's.
Pure Python (no numpy), so the runtime can import it.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import Any

from effortface.core.errors import UserError
from effortface.core.fileio import read_json


@dataclasses.dataclass(frozen=True)
class Blendshape:
    """One blendshape: its ``name``, what it ``drives`` and its ARKit counterparts for export."""

    name: str
    drives: str
    arkit: tuple[str, ...]


@dataclasses.dataclass(frozen=True)
class BlendshapeSet:
    """An ordered set of blendshapes; the order is the annotation order."""

    shapes: tuple[Blendshape, ...]

    @property
    def names(self) -> tuple[str, ...]:
        """Blendshape names in annotation order."""
        return tuple(b.name for b in self.shapes)

    def __len__(self) -> int:
        return len(self.shapes)

    def index(self, name: str) -> int:
        """Position of ``name`` in the set; UserError if it is not a member."""
        try:
            return self.names.index(name)
        except ValueError:
            raise UserError(
                f"blendshape: expected one of {', '.join(self.names)}, found {name!r}"
            ) from None

    def to_dict(self) -> list[dict[str, Any]]:
        """JSON-ready list (for model.json and annotation files)."""
        return [{"name": b.name, "drives": b.drives, "arkit": list(b.arkit)} for b in self.shapes]

    @classmethod
    def from_dict(cls, items: list[dict[str, Any]]) -> BlendshapeSet:
        """Inverse of :meth:`to_dict`.

        Raises
        ------
        UserError
            If ``items`` is not a list of ``{name: str, drives: str, arkit: [str]}`` (names the entry).
        """
        if not isinstance(items, list):
            raise UserError(f"blendshapes: expected a list of {{name, drives, arkit}}, found {type(items).__name__}")
        return cls(tuple(_blendshape(i, d) for i, d in enumerate(items)))


def _blendshape(i: int, d: object) -> Blendshape:
    """One checked entry of a blendshape list (a file may hold any JSON value there)."""
    if not isinstance(d, dict):
        raise UserError(f"blendshapes[{i}]: expected {{name, drives, arkit}}, found {type(d).__name__}")
    name, drives, arkit = d.get("name"), d.get("drives", ""), d.get("arkit", [])
    if not isinstance(name, str) or not name or not isinstance(drives, str) \
            or not isinstance(arkit, list) or not all(isinstance(a, str) for a in arkit):
        raise UserError(f"blendshapes[{i}]: expected {{name: str, drives: str, arkit: [str]}}, found {d!r:.80}")
    return Blendshape(name, drives, tuple(arkit))


DEFAULT_SET = BlendshapeSet((
    Blendshape("mouth_stretch", "exertion, fatigue", ("mouthStretchLeft", "mouthStretchRight")),
    Blendshape("mouth_open", "breathing, fatigue", ("jawOpen",)),
    Blendshape("eye_squint", "exertion, then relaxes with fatigue", ("eyeSquintLeft", "eyeSquintRight")),
    Blendshape("brow_lower", "down with exertion (up with fatigue)", ("browDownLeft", "browDownRight")),
))


def load_blendshape_set(path: str | os.PathLike[str] | None = None) -> BlendshapeSet:
    """Read a blendshape set from a JSON file (a list of {name, drives, arkit}); default if None.

    Raises
    ------
    UserError
        If the file is not a non-empty JSON list of objects with unique names.
    """
    if path is None:
        return DEFAULT_SET
    path = Path(path)
    items = read_json(path, "a JSON list of {name, drives, arkit}")
    try:
        shapes = BlendshapeSet.from_dict(items)
    except (ValueError, KeyError, TypeError, AttributeError) as exc:
        raise UserError(f"{path}: expected a JSON list of {{name, drives, arkit}}, found {exc}") from None
    if not shapes.shapes or len(set(shapes.names)) != len(shapes.names):
        raise UserError(f"{path}: expected unique, non-empty blendshape names, found {shapes.names}")
    return shapes
