"""The machine track as the annotator's guide (Qt-free): per-frame curves, no-face spans, and
sparse key-frames fitted to a curve.

"Accept machine" turns the machine curve over a range of frames into few, editable key-frames
(:func:`fit_keys`): the curve is first smoothed by a running median over :data:`SMOOTH_S` (at least
3 frames), then keys are added greedily where the linear interpolation between the keys misses the
smoothed curve most, until it is within :data:`ACCEPT_TOLERANCE` everywhere or the key budget is
spent: at most one key per :data:`SECONDS_PER_KEY` of the range, so a calm stretch gets few keys and
one that moves gets more. The error to the smoothed curve (RMS and largest) is stated. Frames
without a face get no key. :func:`rdp_keep` (Ramer-Douglas-Peucker) is the older, dense simplification.
"""

from __future__ import annotations

import dataclasses
import heapq
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from scipy.ndimage import median_filter

from effortface.annotate.machine.track import FOUR, read_machine_track

#: default tolerance of "Accept machine" (weight units): no more keys once the fit is this close
ACCEPT_TOLERANCE = 0.03
#: "Accept machine" smooths the machine curve by a running median over this time (at least 3 frames)
SMOOTH_S = 1.0
#: and sets at most one key per this many seconds of the range accepted
SECONDS_PER_KEY = 3.0


@dataclasses.dataclass(frozen=True)
class KeyFit:
    """Key-frames fitted to a machine curve and how close they are.

    Attributes
    ----------
    keys : list of (int, float)
        ``(frame, weight)`` pairs, sorted.
    budget : int
        The most keys the range allowed (one per :data:`SECONDS_PER_KEY`).
    rms, max_error : float
        Error of the keys' linear interpolation to the smoothed curve, over the frames with a face.
    """

    keys: list[tuple[int, float]]
    budget: int
    rms: float
    max_error: float


def smooth_curve(weights: np.ndarray, window_frames: int) -> np.ndarray:
    """Running median of a finite curve over ``window_frames`` (odd; the ends repeat the edge value)."""
    size = max(1, int(window_frames) | 1)
    return median_filter(np.asarray(weights, dtype=float), size=size, mode="nearest")


def window_frames(t_s: np.ndarray, window_s: float = SMOOTH_S) -> int:
    """Odd number of frames spanning ``window_s`` at the video's median frame interval, at least 3."""
    dt = float(np.median(np.diff(t_s))) if np.size(t_s) > 1 else 1.0
    return max(3, int(round(window_s / dt)) | 1) if dt > 0 else 3


def greedy_keep(y: np.ndarray, budget: int, tolerance: float) -> np.ndarray:
    """Indices of at most ``budget`` points (the two ends first) whose linear interpolation follows ``y``.

    A point is added where the interpolation between the points kept misses ``y`` most, until the
    largest miss is within ``tolerance`` or ``budget`` points are kept.

    Parameters
    ----------
    y : numpy.ndarray, shape (n,)
        Finite values at consecutive frames.
    budget : int
        Most points to keep (at least the two ends are kept).
    tolerance : float
        Stop once every sample is within this of the interpolation.

    Returns
    -------
    numpy.ndarray of int
        Sorted indices.
    """
    n = y.size
    if n <= 2:
        return np.arange(n)
    keep = [0, n - 1]
    heap: list[tuple[float, int, int, int]] = []

    def push(a: int, b: int) -> None:
        if b - a < 2:
            return
        x = np.arange(a + 1, b)
        err = np.abs(y[a + 1:b] - (y[a] + (y[b] - y[a]) * (x - a) / (b - a)))
        i = int(np.argmax(err))
        heapq.heappush(heap, (-float(err[i]), a, b, a + 1 + i))

    push(0, n - 1)
    while heap and len(keep) < max(budget, 2) and -heap[0][0] > tolerance:
        _, a, b, m = heapq.heappop(heap)
        keep.append(m)
        push(a, m)
        push(m, b)
    return np.array(sorted(keep))


def fit_keys(curve: np.ndarray, t_s: np.ndarray, tolerance: float = ACCEPT_TOLERANCE,
             seconds_per_key: float = SECONDS_PER_KEY, smooth_s: float = SMOOTH_S) -> KeyFit:
    """Sparse key-frames following a machine curve (NaN where no face) over its frames.

    Parameters
    ----------
    curve : numpy.ndarray, shape (n,)
        The machine's weights on consecutive frames, NaN where no face.
    t_s : numpy.ndarray, shape (n,)
        The frames' times.
    tolerance : float
        No key is added once the fit is within this of the smoothed curve.
    seconds_per_key : float
        The budget: at most ``max(2, duration / seconds_per_key)`` keys over the range.
    smooth_s : float
        Running-median window before the fit (:func:`window_frames`).

    Returns
    -------
    KeyFit
        Frames are indices into ``curve``; no key on a frame without a face.
    """
    y = np.asarray(curve, dtype=float)
    t = np.asarray(t_s, dtype=float)
    stretches = runs(np.isfinite(y))
    duration_s = float(t[-1] - t[0]) if t.size > 1 else 0.0
    budget = max(2, int(duration_s // seconds_per_key))
    win = window_frames(t, smooth_s)
    smoothed = np.full(y.shape, np.nan)
    for a, b in stretches:
        smoothed[a:b + 1] = np.clip(smooth_curve(y[a:b + 1], win), 0.0, 1.0)
    total = sum(b - a + 1 for a, b in stretches) or 1
    keys: list[tuple[int, float]] = []
    for a, b in stretches:  # the budget shared by the stretches' lengths
        share = max(2, budget * (b - a + 1) // total)
        keep = greedy_keep(smoothed[a:b + 1], share, tolerance)
        keys += [(a + int(i), round(float(smoothed[a + i]), 4)) for i in keep]
    fitted = np.full(y.shape, np.nan)
    for a, b in stretches:
        inside = [(f, w) for f, w in keys if a <= f <= b]
        fitted[a:b + 1] = np.interp(np.arange(a, b + 1), [f for f, _ in inside], [w for _, w in inside])
    err = (fitted - smoothed)[np.isfinite(smoothed)]
    return KeyFit(keys, budget, float(np.sqrt(np.mean(err ** 2))) if err.size else 0.0,
                  float(np.max(np.abs(err))) if err.size else 0.0)


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

    def keys(self, name: str, first: int, last: int, t_s: Sequence[float] | np.ndarray,
             tolerance: float = ACCEPT_TOLERANCE) -> KeyFit | None:
        """Sparse key-frames following blendshape ``name`` over frames ``first..last`` (:func:`fit_keys`;
        ``t_s`` the times of every video frame); None when the machine does not rate ``name``."""
        curve = self.curve(name)
        if curve is None:
            return None
        first, last = max(int(first), 0), min(int(last), curve.size - 1)
        fit = fit_keys(curve[first:last + 1], np.asarray(t_s, dtype=float)[first:last + 1], tolerance)
        return dataclasses.replace(fit, keys=[(first + f, w) for f, w in fit.keys])


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
