"""Key-frame tracks and the annotation file ``annotations/<rater>.json`` (pure Python + numpy).

One file per rater and session::

    {
      "schema_version": 1,
      "rater": "R1",
      "session_id": "P01_20260105-101500_cardio",
      "blendshapes": [{"name": "mouth_stretch", "drives": "...", "arkit": [...]}, ...],
      "tracks": {"mouth_stretch": [{"frame": 0, "weight": 0.0, "interp": "linear"}, ...], ...},
      "passes_done": ["mouth_stretch"]
    }

``passes_done`` (optional; files from before it lack it) lists the blendshapes over which the rater
finished a pass of the video (see :mod:`effortface.annotate.completeness`).

``frame`` is a video frame index (a row of ``video_frames.csv``, never time x nominal rate);
``weight`` is in [0, 1]; ``interp`` says how the curve goes from this key to the next one:

- ``hold``: stays at this key's weight until the next key (a step);
- ``linear``: straight line to the next key;
- ``smooth``: smoothstep ``3u^2 - 2u^3`` to the next key (zero slope at both keys, monotone on the
  segment, so it never overshoots [0, 1]).

Before the first key the curve holds the first weight, after the last key the last weight; a track
with no key is "not annotated" and evaluates to NaN.
"""

from __future__ import annotations

import dataclasses
import json
import os
from collections.abc import Iterable, Mapping
from pathlib import Path

import numpy as np

from effortface.core.blendshapes import DEFAULT_SET, BlendshapeSet
from effortface.core.errors import SessionFormatError, UserError
from effortface.core.fileio import atomic_write_text, read_json, refuse_overwrite

SCHEMA_VERSION = 1
INTERPOLATIONS = ("hold", "linear", "smooth")


class AnnotationFormatError(SessionFormatError):
    """An annotation file does not follow the key-frame format."""


@dataclasses.dataclass(frozen=True)
class Keyframe:
    """One key: video ``frame`` index, ``weight`` in [0, 1], ``interp`` towards the next key."""

    frame: int
    weight: float
    interp: str = "linear"

    def __post_init__(self) -> None:
        _check_key(self.frame, self.weight, self.interp)

    def to_dict(self) -> dict:
        """JSON-ready dict ``{frame, weight, interp}``."""
        return {"frame": self.frame, "weight": self.weight, "interp": self.interp}


def _check_key(frame: object, weight: object, interp: object) -> None:
    """Raise UserError naming the field when a key is malformed."""
    if isinstance(frame, bool) or not isinstance(frame, (int, np.integer)) or frame < 0:
        raise UserError(f"key-frame frame: expected an integer >= 0, found {frame!r}")
    if isinstance(weight, bool) or not isinstance(weight, (int, float, np.floating, np.integer)):
        raise UserError(f"key-frame weight: expected a number in [0, 1], found {weight!r:.40}")
    if not 0.0 <= weight <= 1.0:  # compared as is: float() of a huge JSON integer overflows
        raise UserError(f"key-frame weight: expected a number in [0, 1], found {weight!r:.40}")
    if interp not in INTERPOLATIONS:
        raise UserError(
            f"key-frame interp: expected one of {', '.join(INTERPOLATIONS)}, found {interp!r}"
        )


class KeyframeTrack:
    """The key-frames of one blendshape, kept sorted by frame (at most one key per frame).

    Parameters
    ----------
    keys : iterable of Keyframe
        Initial keys, in any order; a later key on the same frame replaces an earlier one.
    """

    def __init__(self, keys: Iterable[Keyframe] = ()) -> None:
        self._keys: dict[int, Keyframe] = {}
        for key in keys:
            self._keys[int(key.frame)] = key

    @property
    def keys(self) -> tuple[Keyframe, ...]:
        """The keys sorted by frame."""
        return tuple(self._keys[f] for f in sorted(self._keys))

    def __len__(self) -> int:
        return len(self._keys)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, KeyframeTrack) and self.keys == other.keys

    def __repr__(self) -> str:
        return f"KeyframeTrack({list(self.keys)!r})"

    def copy(self) -> KeyframeTrack:
        """An independent copy (keys are immutable, so a shallow copy suffices)."""
        return KeyframeTrack(self.keys)

    def add(self, frame: int, weight: float, interp: str = "linear") -> Keyframe:
        """Add a key, replacing any key already on ``frame``; return the new key."""
        key = Keyframe(int(frame), float(weight), interp)
        self._keys[key.frame] = key
        return key

    def get(self, frame: int) -> Keyframe | None:
        """The key on ``frame``, or None."""
        return self._keys.get(int(frame))

    def delete(self, frame: int) -> Keyframe:
        """Remove and return the key on ``frame``; KeyError if there is none."""
        try:
            return self._keys.pop(int(frame))
        except KeyError:
            raise KeyError(f"no key-frame on frame {frame}") from None

    def move(self, frame: int, new_frame: int, weight: float | None = None) -> Keyframe:
        """Move the key on ``frame`` to ``new_frame`` (and optionally a new weight).

        Raises
        ------
        KeyError
            If there is no key on ``frame``.
        ValueError
            If another key already sits on ``new_frame``.
        """
        old = self._keys.get(int(frame))
        if old is None:
            raise KeyError(f"no key-frame on frame {frame}")
        if int(new_frame) != old.frame and int(new_frame) in self._keys:
            raise ValueError(f"cannot move key-frame {frame} to {new_frame}: frame already keyed")
        new = Keyframe(int(new_frame), old.weight if weight is None else float(weight), old.interp)
        del self._keys[old.frame]
        self._keys[new.frame] = new
        return new

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Sorted key frames (int), weights (float) and interpolation codes (index in INTERPOLATIONS)."""
        keys = self.keys
        frames = np.array([k.frame for k in keys], dtype=np.int64)
        weights = np.array([k.weight for k in keys], dtype=float)
        codes = np.array([INTERPOLATIONS.index(k.interp) for k in keys], dtype=np.int64)
        return frames, weights, codes

    def evaluate(self, frames: Iterable[float] | np.ndarray | float) -> np.ndarray:
        """Weights at ``frames`` (vectorised; fractional frames allowed).

        Parameters
        ----------
        frames : array-like of float
            Frame indices to evaluate at.

        Returns
        -------
        numpy.ndarray
            Weights in [0, 1], same shape as ``frames``; all NaN when the track has no key.
        """
        x = np.asarray(frames, dtype=float)
        kf, kw, kc = self.arrays()
        if kf.size == 0:
            return np.full(x.shape, np.nan)
        if kf.size == 1:
            return np.full(x.shape, kw[0])
        seg = np.clip(np.searchsorted(kf, x, side="right") - 1, 0, kf.size - 2)
        u = np.clip((x - kf[seg]) / (kf[seg + 1] - kf[seg]), 0.0, 1.0)
        shape = np.select([kc[seg] == 0, kc[seg] == 1], [np.zeros_like(u), u], u * u * (3 - 2 * u))
        shape = np.where(x >= kf[-1], 1.0, shape)  # past the last key: hold its weight
        return kw[seg] + (kw[seg + 1] - kw[seg]) * shape

    def to_list(self) -> list[dict]:
        """JSON-ready list of key dicts, sorted by frame."""
        return [k.to_dict() for k in self.keys]


@dataclasses.dataclass
class RaterAnnotations:
    """One rater's key-frames for one session: a track per blendshape of ``blendshapes``.

    Attributes
    ----------
    rater : str
        Rater code (also the file name stem: ``annotations/<rater>.json``).
    session_id : str
        The session folder's name.
    blendshapes : BlendshapeSet
        The set annotated, in annotation order.
    tracks : dict of str to KeyframeTrack
        One track per blendshape name (created empty when missing).
    passes_done : set of str or None
        Blendshapes whose pass over the video the rater finished; None when the file does not say.
    """

    rater: str
    session_id: str
    blendshapes: BlendshapeSet = DEFAULT_SET
    tracks: dict[str, KeyframeTrack] = dataclasses.field(default_factory=dict)
    passes_done: set[str] | None = dataclasses.field(default=None, compare=False)

    def __post_init__(self) -> None:
        for name in self.tracks:
            self.blendshapes.index(name)  # UserError for a name outside the set
        for name in self.blendshapes.names:
            self.tracks.setdefault(name, KeyframeTrack())

    def copy(self) -> RaterAnnotations:
        """An independent copy (for undo snapshots)."""
        return RaterAnnotations(self.rater, self.session_id, self.blendshapes,
                                {n: t.copy() for n, t in self.tracks.items()},
                                None if self.passes_done is None else set(self.passes_done))

    def weights(self, frames: Iterable[float] | np.ndarray) -> np.ndarray:
        """Per-frame weights, shape ``(len(frames), n_blendshapes)``, NaN where not annotated."""
        x = np.asarray(frames, dtype=float)
        return np.column_stack([self.tracks[n].evaluate(x) for n in self.blendshapes.names])

    def to_dict(self) -> dict:
        """The JSON document (see the module docstring)."""
        doc = {
            "schema_version": SCHEMA_VERSION,
            "rater": self.rater,
            "session_id": self.session_id,
            "blendshapes": self.blendshapes.to_dict(),
            "tracks": {n: self.tracks[n].to_list() for n in self.blendshapes.names},
        }
        if self.passes_done is not None:
            doc["passes_done"] = [n for n in self.blendshapes.names if n in self.passes_done]
        return doc

    def save(self, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
        """Write the file atomically (temp file in the same folder, fsync, ``os.replace``).

        Parameters
        ----------
        path : path-like
            Target file, usually ``<session>/annotations/<rater>.json``; its folder is created.
        overwrite : bool
            Replace an existing file (autosave); otherwise an existing file is refused.

        Returns
        -------
        Path
            The written path.

        Raises
        ------
        FileExistsError
            If ``path`` exists and ``overwrite`` is False.
        """
        path = refuse_overwrite(path, overwrite=overwrite, what="annotation file")
        path.parent.mkdir(parents=True, exist_ok=True)
        text = json.dumps(self.to_dict(), indent=1) + "\n"
        atomic_write_text(path, text)
        return path


def read_annotations(path: str | os.PathLike, *, session_id: str | None = None,
                     rater: str | None = None) -> RaterAnnotations:
    """Read an ``annotations/<rater>.json`` file.

    Parameters
    ----------
    path : path-like
        The file.
    session_id, rater : str, optional
        The session and rater the file must belong to (a file copied from another session, or
        another rater's file under this name, is refused).

    Returns
    -------
    RaterAnnotations

    Raises
    ------
    AnnotationFormatError
        If the file is not JSON, has another schema version, or a field or key is malformed;
        the message names the file and the field.
    """
    path = Path(path)
    doc = read_json(path, "a JSON annotation file", AnnotationFormatError)
    try:
        ann = _from_dict(doc)
    except UserError as exc:
        raise AnnotationFormatError(f"{path}: {exc}") from None
    for field, wanted in (("session_id", session_id), ("rater", rater)):
        found = getattr(ann, field)
        if wanted is not None and found != wanted:
            raise AnnotationFormatError(f"{path}: {field}: expected {wanted!r} (this file's "
                                        f"{'session' if field == 'session_id' else 'name'}), found {found!r}")
    return ann


def _from_dict(doc: object) -> RaterAnnotations:
    """Build annotations from a parsed document; UserError naming the bad field."""
    if not isinstance(doc, Mapping):
        raise UserError(f"expected a JSON object, found {type(doc).__name__}")
    if isinstance(doc.get("schema_version"), bool) or doc.get("schema_version") != SCHEMA_VERSION:
        raise UserError(
            f"schema_version: expected {SCHEMA_VERSION}, found {doc.get('schema_version')!r}"
        )
    for field in ("rater", "session_id"):
        if not isinstance(doc.get(field), str) or not doc[field]:
            raise UserError(f"{field}: expected a non-empty string, found {doc.get(field)!r}")
    shapes = _read_blendshapes(doc.get("blendshapes"))
    tracks_doc = doc.get("tracks")
    if not isinstance(tracks_doc, Mapping):
        raise UserError(f"tracks: expected an object of blendshape -> keys, found {tracks_doc!r}")
    tracks = {name: _read_track(name, keys) for name, keys in tracks_doc.items()}
    done = doc.get("passes_done")
    if done is not None and (not isinstance(done, list) or not set(done) <= set(shapes.names)):
        raise UserError(f"passes_done: expected a list of blendshapes of the set, found {done!r}")
    return RaterAnnotations(doc["rater"], doc["session_id"], shapes, tracks,
                            None if done is None else set(done))


def _read_blendshapes(items: object) -> BlendshapeSet:
    """The blendshape set of a document; UserError if malformed."""
    try:
        shapes = BlendshapeSet.from_dict(items)  # type: ignore[arg-type]  # malformed: caught below
    except (TypeError, KeyError, AttributeError):
        raise UserError(f"blendshapes: expected a list of {{name, drives, arkit}}, found {items!r}") from None
    if not shapes.shapes or len(set(shapes.names)) != len(shapes.names):
        raise UserError(f"blendshapes: expected unique, non-empty names, found {shapes.names}")
    return shapes


def _read_track(name: str, keys: object) -> KeyframeTrack:
    """One track from its JSON list; UserError naming the blendshape and the key index."""
    if not isinstance(keys, list):
        raise UserError(f"tracks.{name}: expected a list of key-frames, found {keys!r}")
    out = KeyframeTrack()
    for i, item in enumerate(keys):
        if not isinstance(item, Mapping) or not {"frame", "weight"} <= set(item):
            raise UserError(f"tracks.{name}[{i}]: expected {{frame, weight, interp}}, found {item!r}")
        try:
            key = Keyframe(item["frame"], item["weight"], item.get("interp", "linear"))
        except UserError as exc:
            raise UserError(f"tracks.{name}[{i}]: {exc}") from None
        if out.get(key.frame) is not None:
            raise UserError(f"tracks.{name}[{i}]: expected one key per frame, found frame {key.frame} twice")
        out.add(key.frame, key.weight, key.interp)
    return out
