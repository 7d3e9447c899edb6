"""Key-frame tracks and the annotation file ``annotations/<rater>.json`` (pure Python + numpy).

One file per rater and session::

    {
      "schema_version": 2,
      "rater": "R1",
      "session_id": "P01_20260105-101500_cardio",
      "blendshapes": [{"name": "mouth_stretch", "drives": "...", "arkit": [...]}, ...],
      "tracks": {"mouth_stretch": [{"frame": 0, "weight": 0.0, "interp": "linear", "origin": "typed"},
                                   {"frame": 90, "weight": 0.3, "interp": "linear", "origin": "machine",
                                    "accepted_by": "R1"}, ...], ...},
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

``origin`` (schema version 2) says who set the key:

- ``typed``: the rater typed it (every key of a version 1 file, which had no origins, loads as typed);
- ``machine``: "Accept machine" set it from the machine track, ``accepted_by`` names the rater who
  accepted it; it stays the machine's label (left out of human-only training and the human mean);
- ``edited``: a machine key the rater then changed (weight, frame or interpolation): the rater's.

Before the first key the curve holds the first weight, after the last key the last weight; a track
with no key is "not annotated" and evaluates to NaN.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from effortface.core.blendshapes import DEFAULT_SET, BlendshapeSet
from effortface.core.bounds import BOUNDS
from effortface.core.errors import SessionFormatError, UserError
from effortface.core.fileio import atomic_write_text, read_json, refuse_overwrite

SCHEMA_VERSION = 2
#: versions :func:`read_annotations` reads (version 1 had no key origins: its keys load as typed)
READABLE_VERSIONS = (1, 2)
INTERPOLATIONS = ("hold", "linear", "smooth")
#: who set a key: typed by the rater, accepted from the machine, or the machine's then edited by the rater
ORIGINS = ("typed", "machine", "edited")
#: origins that count as a person's label (human-only training, the human mean)
HUMAN_ORIGINS = ("typed", "edited")


#: the frame numbers a key may carry (a frame beyond it overflowed numpy in agreement and train)
FRAME_BOUND = BOUNDS["frame"]


class AnnotationFormatError(SessionFormatError):
    """An annotation file does not follow the key-frame format."""


@dataclasses.dataclass(frozen=True)
class Keyframe:
    """One key: video ``frame`` index, ``weight`` in [0, 1], ``interp`` towards the next key, its
    ``origin`` (one of :data:`ORIGINS`) and, for a machine key, the rater who accepted it."""

    frame: int
    weight: float
    interp: str = "linear"
    origin: str = "typed"
    accepted_by: str | None = None

    def __post_init__(self) -> None:
        _check_key(self.frame, self.weight, self.interp)
        if self.origin not in ORIGINS:
            raise UserError(f"key-frame origin: expected one of {', '.join(ORIGINS)}, found {self.origin!r}")
        if (self.origin == "machine") != isinstance(self.accepted_by, str) or self.accepted_by == "":
            raise UserError(f"key-frame accepted_by: expected the accepting rater's code on a machine key "
                            f"(and only there), found {self.accepted_by!r} on a {self.origin} key")

    @property
    def human(self) -> bool:
        """Whether a person set this key (typed, or a machine key they edited)."""
        return self.origin in HUMAN_ORIGINS

    def edited(self, **changes: Any) -> Keyframe:
        """This key changed by the rater: a machine key becomes ``edited`` (the rater's)."""
        if self.origin == "machine":
            changes = {"origin": "edited", "accepted_by": None, **changes}
        return dataclasses.replace(self, **changes)

    def to_dict(self) -> dict:
        """JSON-ready dict ``{frame, weight, interp, origin[, accepted_by]}``."""
        doc: dict[str, Any] = {"frame": self.frame, "weight": self.weight, "interp": self.interp,
                               "origin": self.origin}
        if self.accepted_by is not None:
            doc["accepted_by"] = self.accepted_by
        return doc


def _check_key(frame: object, weight: object, interp: object) -> None:
    """Raise UserError naming the field when a key is malformed."""
    if isinstance(frame, bool) or not isinstance(frame, (int, np.integer)) or frame < 0:
        raise UserError(f"key-frame frame: expected an integer >= 0, found {frame!r:.40}")
    if frame > FRAME_BOUND.high:  # compared as is: float() of a huge JSON integer overflows
        raise UserError(f"key-frame frame: expected an integer from 0 to {FRAME_BOUND.high:g}, found {frame!r:.40}")
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

    def add(self, frame: int, weight: float, interp: str = "linear", origin: str = "typed",
            accepted_by: str | None = None) -> Keyframe:
        """Add a key, replacing any key already on ``frame``; return the new key."""
        key = Keyframe(int(frame), float(weight), interp, origin, accepted_by)
        self._keys[key.frame] = key
        return key

    def put(self, key: Keyframe) -> Keyframe:
        """Add ``key`` as it is (origin included), replacing any key on its frame; return it."""
        self._keys[int(key.frame)] = key
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
        new = old.edited(frame=int(new_frame), weight=old.weight if weight is None else float(weight))
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

    def origins(self, frames: Iterable[float] | np.ndarray) -> np.ndarray:
        """The origin of the label at each of ``frames``: that of the nearest key (the earlier on a tie).

        Returns
        -------
        numpy.ndarray of str
            One of :data:`ORIGINS` per frame; ``""`` everywhere when the track has no key.
        """
        x = np.asarray(frames, dtype=float)
        keys = self.keys
        if not keys:
            return np.full(x.shape, "", dtype=object)
        kf = np.array([k.frame for k in keys], dtype=float)
        i = np.clip(np.searchsorted(kf, x), 1, max(kf.size - 1, 1)) if kf.size > 1 else np.zeros(x.shape, int)
        if kf.size > 1:
            i = np.where(np.abs(x - kf[i - 1]) <= np.abs(kf[i] - x), i - 1, i)
        return np.array([k.origin for k in keys], dtype=object)[i]

    def human_mask(self, frames: Iterable[float] | np.ndarray) -> np.ndarray:
        """True at the frames whose label a person set (nearest key typed or edited, see :meth:`origins`)."""
        return np.isin(self.origins(frames), HUMAN_ORIGINS)

    def evaluate_human(self, frames: Iterable[float] | np.ndarray) -> np.ndarray:
        """:meth:`evaluate`, NaN where the label is the machine's (nearest key accepted, not edited)."""
        x = np.asarray(frames, dtype=float)
        return np.where(self.human_mask(x), self.evaluate(x), np.nan)


def origin_seconds(track: KeyframeTrack, frame_times_s: Iterable[float] | np.ndarray) -> dict[str, int]:
    """Seconds of the video whose label is of each origin (the frame nearest each whole second).

    Parameters
    ----------
    track : KeyframeTrack
        One blendshape's keys.
    frame_times_s : array-like of float
        Arrival time of each video frame (``video_frames.csv``), increasing.

    Returns
    -------
    dict of str to int
        ``{"typed": n, "machine": n, "edited": n}``; all 0 for a track with no key.
    """
    t = np.asarray(frame_times_s, dtype=float)
    if t.size == 0 or not len(track):
        return {o: 0 for o in ORIGINS}
    seconds = np.arange(math.ceil(t[0]), math.floor(t[-1]) + 1.0)
    frames = np.clip(np.searchsorted(t, seconds), 0, t.size - 1)
    found = track.origins(frames)
    return {o: int(np.count_nonzero(found == o)) for o in ORIGINS}


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
        If the file is not JSON, has a schema version other than 1 or 2, or a field or key is malformed;
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
    version = doc.get("schema_version")
    if isinstance(version, bool) or version not in READABLE_VERSIONS:
        raise UserError(
            f"schema_version: expected {' or '.join(map(str, READABLE_VERSIONS))}, found {version!r}"
        )
    for field in ("rater", "session_id"):
        if not isinstance(doc.get(field), str) or not doc[field]:
            raise UserError(f"{field}: expected a non-empty string, found {doc.get(field)!r}")
    shapes = _read_blendshapes(doc.get("blendshapes"))
    tracks_doc = doc.get("tracks")
    if not isinstance(tracks_doc, Mapping):
        raise UserError(f"tracks: expected an object of blendshape -> keys, found {tracks_doc!r}")
    tracks = {name: _read_track(name, keys, with_origin=version >= 2) for name, keys in tracks_doc.items()}
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


def _read_track(name: str, keys: object, *, with_origin: bool = True) -> KeyframeTrack:
    """One track from its JSON list; UserError naming the blendshape and the key index.

    ``with_origin`` False (a version 1 file): the keys carry no origin and load as typed.
    """
    if not isinstance(keys, list):
        raise UserError(f"tracks.{name}: expected a list of key-frames, found {keys!r}")
    out = KeyframeTrack()
    for i, item in enumerate(keys):
        if not isinstance(item, Mapping) or not {"frame", "weight"} <= set(item):
            raise UserError(f"tracks.{name}[{i}]: expected {{frame, weight, interp}}, found {item!r}")
        origin = (item.get("origin", "typed"), item.get("accepted_by")) if with_origin else ("typed", None)
        try:
            key = Keyframe(item["frame"], item["weight"], item.get("interp", "linear"), *origin)
        except UserError as exc:
            raise UserError(f"tracks.{name}[{i}]: {exc}") from None
        if out.get(key.frame) is not None:
            raise UserError(f"tracks.{name}[{i}]: expected one key per frame, found frame {key.frame} twice")
        out.put(key)
    return out
