"""From MediaPipe's 52 scores to our four blendshapes, and onto the lab's rating scale.

**Mapping.** Each blendshape is the mean of the ARKit scores its definition names
(docs/SCIENCE.md section 5, the ``arkit`` field of :data:`effortface.core.blendshapes.DEFAULT_SET`):

============== ============================================ ==============================================
blendshape     ARKit scores (mean)                          why
============== ============================================ ==============================================
mouth_stretch  mouthStretchLeft, mouthStretchRight           lip corners pulled out and down (exertion)
mouth_open     jawOpen                                      the jaw drop of heavy breathing; not
                                                            mouthClose (lips held together over an open
                                                            jaw) nor mouthLowerDown (lip, not jaw)
eye_squint     eyeSquintLeft, eyeSquintRight                lower lids raised; not eyeBlink (a closed eye
                                                            is not a squint)
brow_lower     browDownLeft, browDownRight                  brows lowered; browInnerUp is its opposite
============== ============================================ ==============================================

Left and right are averaged: our blendshapes are symmetric. This is the definition mapping of sidecar
format 1; ``effortface preannotate`` now rates with the effort mapping built on the same scores
(:mod:`effortface.annotate.machine.effort`) and, where it wins held out, the learned one
(:mod:`effortface.annotate.machine.learned`).

**Calibration.** MediaPipe's scores are not the lab's ratings: a rater's "0.6 mouth open" is not a
``jawOpen`` of 0.6. Where humans keyed the participant, each blendshape gets a monotone (isotonic,
non-decreasing, clipped to [0, 1]) map from the raw mapped score to the human weights at the keyed
frames (scikit-learn ``IsotonicRegression``), fitted per participant on every key of every rater in
the participant's sessions that have a machine rating (this one included). Its error is stated:
the mean absolute error on the keys it was fitted to, and a held-out one (5-fold cross-validation
over the keys) that tells how far it can be trusted between keys. Fewer than
:data:`MIN_KEYS` keys (or no spread in the raw score) leaves that blendshape raw, said so.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from effortface.annotate.machine.landmarker import ARKIT_NAMES
from effortface.core.blendshapes import DEFAULT_SET, BlendshapeSet

#: the fewest (raw, human) pairs a blendshape's calibration is fitted on
MIN_KEYS = 5
#: folds of the held-out error (fewer when there are fewer keys)
HELDOUT_FOLDS = 5
RAW_KIND = "raw: no human key-frames"


def default_mapping(blendshapes: BlendshapeSet = DEFAULT_SET) -> dict[str, tuple[str, ...]]:
    """Blendshape name -> the ARKit names averaged for it (from the set's ``arkit`` field)."""
    out = {}
    for b in blendshapes.shapes:
        unknown = [a for a in b.arkit if a not in ARKIT_NAMES]
        if unknown or not b.arkit:
            raise ValueError(f"blendshape {b.name}: expected ARKit names of MediaPipe's 52, found {list(b.arkit)}")
        out[b.name] = tuple(b.arkit)
    return out


def map_scores(scores: np.ndarray, mapping: dict[str, tuple[str, ...]], names: Sequence[str]) -> np.ndarray:
    """(n, 52) scores -> (n, len(names)) raw weights, the mean of each blendshape's ARKit columns (NaN stays NaN)."""
    index = {a: i for i, a in enumerate(ARKIT_NAMES)}
    return np.column_stack([scores[:, [index[a] for a in mapping[name]]].mean(axis=1) for name in names])


@dataclasses.dataclass
class Calibration:
    """A per-blendshape monotone map from raw mapped scores to the lab's scale.

    Attributes
    ----------
    participant : str
        The participant it was fitted for.
    curves : dict of str to (x, y)
        Per calibrated blendshape, the isotonic fit's breakpoints (raw score -> weight, linear between).
    report : dict of str to dict
        Per blendshape: ``kind`` ("isotonic" or the raw reason), ``n_keys``, ``fit_mae``, ``heldout_mae``.
    """

    participant: str
    curves: dict[str, tuple[np.ndarray, np.ndarray]]
    report: dict[str, dict[str, Any]]

    @property
    def kind(self) -> str:
        """What the sidecar says of the whole: isotonic for some blendshapes, or raw."""
        return "isotonic per participant" if self.curves else RAW_KIND

    def apply(self, raw: np.ndarray, names: Sequence[str]) -> np.ndarray:
        """Calibrated (n, len(names)) weights; blendshapes without a curve pass raw (NaN stays NaN)."""
        out = raw.astype(float).copy()
        for j, name in enumerate(names):
            if name in self.curves:
                x, y = self.curves[name]
                ok = ~np.isnan(raw[:, j])
                out[ok, j] = np.interp(raw[ok, j], x, y)
        return out

    def to_dict(self) -> dict[str, Any]:
        """The sidecar's ``calibration`` object."""
        return {"kind": self.kind, "participant": self.participant,
                "method": "sklearn IsotonicRegression (non-decreasing, clipped to [0, 1]) from the raw mapped "
                          "score to the human key-frame weights of every rater",
                "blendshapes": {n: {**r, **({"x": [round(float(v), 6) for v in self.curves[n][0]],
                                             "y": [round(float(v), 6) for v in self.curves[n][1]]}
                                            if n in self.curves else {})}
                                for n, r in self.report.items()}}


def _isotonic(x: np.ndarray, y: np.ndarray) -> Any:
    from sklearn.isotonic import IsotonicRegression

    return IsotonicRegression(y_min=0.0, y_max=1.0, increasing=True, out_of_bounds="clip").fit(x, y)


def _heldout_mae(x: np.ndarray, y: np.ndarray) -> float | None:
    """Mean absolute error of isotonic fits on keys they did not see (k-fold, fixed shuffle)."""
    folds = min(HELDOUT_FOLDS, len(x) // 2)
    if folds < 2:
        return None
    order = np.random.default_rng(0).permutation(len(x))
    errors = []
    for k in range(folds):
        test = order[k::folds]
        train = np.setdiff1d(order, test)
        if np.ptp(x[train]) == 0:
            return None
        errors.append(np.abs(_isotonic(x[train], y[train]).predict(x[test]) - y[test]))
    return float(np.mean(np.concatenate(errors)))


def fit_calibration(participant: str, raw: np.ndarray, human: np.ndarray, names: Sequence[str]) -> Calibration:
    """Fit one blendshape's isotonic map per column from (raw, human) pairs.

    Parameters
    ----------
    participant : str
        Whose keys these are (for the record).
    raw : numpy.ndarray
        (k, len(names)) raw mapped scores at keyed frames (NaN: no face, or not keyed).
    human : numpy.ndarray
        (k, len(names)) human key weights at the same frames (NaN where that blendshape was not keyed).
    names : sequence of str
        The blendshapes, in column order.
    """
    curves: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    report: dict[str, dict[str, Any]] = {}
    for j, name in enumerate(names):
        ok = ~np.isnan(raw[:, j]) & ~np.isnan(human[:, j])
        x, y = raw[ok, j], human[ok, j]
        if len(x) < MIN_KEYS or np.ptp(x) == 0:
            why = "no human key-frames" if len(x) == 0 else f"{len(x)} human keys (fewer than {MIN_KEYS})" \
                if len(x) < MIN_KEYS else "no spread in the machine's score at the keys"
            report[name] = {"kind": f"raw: {why}", "n_keys": int(len(x))}
            continue
        model = _isotonic(x, y)
        xs = np.asarray(model.X_thresholds_, dtype=float)
        ys = np.asarray(model.y_thresholds_, dtype=float)
        heldout = _heldout_mae(x, y)
        curves[name] = (xs, ys)
        report[name] = {"kind": "isotonic", "n_keys": int(len(x)),
                        "fit_mae": round(float(np.mean(np.abs(np.interp(x, xs, ys) - y))), 4),
                        "heldout_mae": None if heldout is None else round(heldout, 4)}
    return Calibration(participant, curves, report)


def human_keys(session_dir: Path, frames: np.ndarray, names: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    """Every rater's key-frames of a session: (frame indices into ``frames``, (k, len(names)) weights).

    One row per (rater, keyed frame); a blendshape that rater did not key at that frame is NaN.
    Annotation files that cannot be read are skipped (Annotate and train report them).
    """
    from effortface.annotate.keyframes import read_annotations
    from effortface.core.errors import UserError

    rows_i: list[int] = []
    rows_w: list[list[float]] = []
    position = {int(f): i for i, f in enumerate(frames)}
    for path in sorted((Path(session_dir) / "annotations").glob("*.json")):
        try:
            ann = read_annotations(path)
        except UserError:
            continue
        keyed: dict[int, list[float]] = {}
        for j, name in enumerate(names):
            track = ann.tracks.get(name)
            for key in (track.keys if track is not None else ()):
                if key.frame in position and key.human:  # never calibrate on its own accepted keys
                    keyed.setdefault(key.frame, [float("nan")] * len(names))[j] = float(key.weight)
        for frame, weights in sorted(keyed.items()):
            rows_i.append(position[frame])
            rows_w.append(weights)
    return np.asarray(rows_i, dtype=int), np.asarray(rows_w, dtype=float).reshape(len(rows_w), len(names))


def calibration_pairs(sessions: Iterable[tuple[Path, np.ndarray, np.ndarray]],
                      names: Sequence[str]) -> tuple[np.ndarray, np.ndarray]:
    """Stack (raw, human) pairs over sessions given as (folder, frame numbers, (n, len(names)) raw scores)."""
    raws, humans = [], []
    for folder, frames, raw in sessions:
        index, weights = human_keys(folder, frames, names)
        raws.append(raw[index])
        humans.append(weights)
    if not raws:
        return np.empty((0, len(names))), np.empty((0, len(names)))
    return np.concatenate(raws), np.concatenate(humans)
