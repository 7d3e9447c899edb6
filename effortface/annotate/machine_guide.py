"""The machine track as the annotator's guide (Qt-free): per-frame curves, no-face spans, and
key-frames from a curve by Ramer-Douglas-Peucker simplification.

"Accept machine" turns the machine curve over a range of frames into key-frames: each stretch of
frames with a face is simplified by Ramer-Douglas-Peucker with a *vertical* tolerance (the weight the
linear interpolation between two kept points may miss a machine value by, default
:data:`ACCEPT_TOLERANCE` = 0.03 of the weight range), so the keys reproduce the machine curve within
the tolerance at every frame of the stretch; frames without a face get no key.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from effortface.annotate.machine.track import FOUR, read_machine_track

#: default tolerance of "Accept machine" (weight units)
ACCEPT_TOLERANCE = 0.03


def rdp_keep(weights: np.ndarray, tolerance: float = ACCEPT_TOLERANCE) -> np.ndarray:
    """Indices of the points Ramer-Douglas-Peucker keeps on a curve sampled at consecutive frames.

    The distance is vertical (in weight units): linear interpolation between the kept points is
    within ``tolerance`` of every sample. The first and last points are always kept.

    Parameters
    ----------
    weights : numpy.ndarray, shape (n,)
        Finite values at frames 0..n-1.
    tolerance : float
        Largest vertical error allowed, >= 0.

    Returns
    -------
    numpy.ndarray of int
        Sorted indices.
    """
    y = np.asarray(weights, dtype=float)
    n = y.size
    if n <= 2:
        return np.arange(n)
    keep = np.zeros(n, bool)
    keep[[0, n - 1]] = True
    stack = [(0, n - 1)]
    while stack:
        a, b = stack.pop()
        if b - a < 2:
            continue
        x = np.arange(a + 1, b)
        err = np.abs(y[a + 1:b] - (y[a] + (y[b] - y[a]) * (x - a) / (b - a)))
        i = int(np.argmax(err))
        if err[i] > tolerance:
            m = a + 1 + i
            keep[m] = True
            stack += [(a, m), (m, b)]
    return np.flatnonzero(keep)


def runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """``(first, last)`` index pairs of the runs of True in ``mask`` (inclusive)."""
    m = np.concatenate([[False], np.asarray(mask, bool), [False]])
    edges = np.flatnonzero(np.diff(m.astype(np.int8)))
    return [(int(a), int(b) - 1) for a, b in zip(edges[::2], edges[1::2])]


@dataclasses.dataclass
class MachineGuide:
    """A session's machine track laid on its video frames.

    Attributes
    ----------
    weights : numpy.ndarray, shape (n_frames, 4)
        The four weights (:data:`~effortface.annotate.machine.track.FOUR` order), NaN where no face
        or where the track has no row for the frame.
    no_face : numpy.ndarray of bool, shape (n_frames,)
        Frames the machine rated and found no face on.
    source : Path
        The track's folder.
    """

    weights: np.ndarray
    no_face: np.ndarray
    source: Path

    def curve(self, name: str) -> np.ndarray | None:
        """Per-frame weights of blendshape ``name``; None when the machine does not rate it."""
        return self.weights[:, FOUR.index(name)].copy() if name in FOUR else None

    def no_face_spans(self) -> list[tuple[int, int]]:
        """``(first, last)`` frames of each stretch without a face."""
        return runs(self.no_face)

    def keys(self, name: str, first: int, last: int, tolerance: float = ACCEPT_TOLERANCE
             ) -> list[tuple[int, float]]:
        """Key-frames ``(frame, weight)`` reproducing blendshape ``name`` over ``first..last`` within
        ``tolerance`` (:func:`rdp_keep` on each stretch with a face; none where no face)."""
        curve = self.curve(name)
        if curve is None:
            return []
        first, last = max(int(first), 0), min(int(last), curve.size - 1)
        out: list[tuple[int, float]] = []
        for a, b in runs(np.isfinite(curve[first:last + 1])):
            segment = curve[first + a:first + b + 1]
            out += [(first + a + int(i), round(float(np.clip(segment[i], 0.0, 1.0)), 4))
                    for i in rdp_keep(segment, tolerance)]
        return out


def load_guide(session_dir: str | Path, n_frames: int) -> MachineGuide | None:
    """The session's machine track on its ``n_frames`` video frames; None when it has none."""
    track = read_machine_track(Path(session_dir))
    if track is None:
        return None
    weights = np.full((n_frames, len(FOUR)), np.nan)
    no_face = np.zeros(n_frames, bool)
    ok = (track.frame >= 0) & (track.frame < n_frames)
    rows = track.frame[ok]
    weights[rows] = np.where(track.face[ok, None], track.weights[ok], np.nan)
    no_face[rows] = ~track.face[ok]
    return MachineGuide(weights, no_face, Path(session_dir) / "machine")
