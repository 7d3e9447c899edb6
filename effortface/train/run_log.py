"""What a training run shows beyond the paper's figures (Qt-free): the run log's tables and timings,
and the settings that make two model bundles comparable or not.

The Train stage's run log (:class:`effortface.train.gui.train_stage.QtRunLog`) shows
:func:`fold_scores`, :func:`grid_table` and :func:`held_out_pairs` of a
:class:`~effortface.train.pipeline.TrainingOutcome`, with :func:`eta_s` while it runs; its Compare
view shows :func:`bundle_settings` of each bundle and :func:`cv_caption` over their scores.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pandas as pd

from effortface.train.face_fit import GRIDS, cv_folds, held_out_predictions
from effortface.train.pipeline import TrainingOutcome

#: what each cross-validation choice is called on screen
CV_LABELS = {"lopo": "leave one participant out", "kfold": "random-frame K-fold (inflated)"}
#: what each grid of :data:`effortface.train.face_fit.GRIDS` is for (the settings' tooltips)
GRID_NOTES = {
    "small": "quick: the SVR's C, gamma and epsilon searched over few values (a minute on the sample lab)",
    "paper": "wide: more values of C, gamma and epsilon (about 15x the time of small)",
}


def grid_tooltip(name: str) -> str:
    """A grid's purpose and values, for a tooltip (C: penalty, gamma: RBF width, epsilon: tube)."""
    grid = GRIDS[name]
    values = "; ".join(f"{k} {', '.join(f'{v:g}' for v in vs)}" for k, vs in grid.items())
    n = math.prod(len(v) for v in grid.values())
    return (f"{name}: {GRID_NOTES.get(name, '')}.\n{values} ({n} points per blendshape, each fitted "
            "on every CV fold).\nC: penalty on errors (larger fits closer); gamma: RBF kernel width "
            "on standardised features (larger = more local); epsilon: error tolerated without "
            "penalty, in normalised weight.")


def eta_s(fraction: float, elapsed_s: float) -> float:
    """Seconds left at ``fraction`` done after ``elapsed_s`` (linear; NaN before any progress)."""
    if fraction <= 0.0 or not math.isfinite(elapsed_s):
        return float("nan")
    return max(elapsed_s * (1.0 - fraction) / fraction, 0.0)


def timing_text(fraction: float, elapsed_s: float) -> str:
    """``"12 s elapsed, about 30 s left"`` (no estimate before the first step)."""
    left = eta_s(fraction, elapsed_s)
    eta = "" if not math.isfinite(left) or fraction >= 1.0 else f", about {left:.0f} s left"
    return f"{elapsed_s:.0f} s elapsed{eta}"


def _r(y: np.ndarray, pred: np.ndarray) -> float:
    ok = np.isfinite(y) & np.isfinite(pred)
    if ok.sum() < 3 or np.std(y[ok]) == 0 or np.std(pred[ok]) == 0:
        return float("nan")
    return float(np.corrcoef(y[ok], pred[ok])[0, 1])


def _rmse(y: np.ndarray, pred: np.ndarray) -> float:
    ok = np.isfinite(y) & np.isfinite(pred)
    return float(np.sqrt(np.mean((y[ok] - pred[ok]) ** 2))) if ok.any() else float("nan")


def fold_scores(outcome: TrainingOutcome) -> pd.DataFrame:
    """Per CV fold of the face fit and blendshape: held-out r and RMSE of the chosen SVR.

    Long format, one row per fold and blendshape: ``fold``, ``held out`` (participants, or a row
    count for random-frame folds), ``blendshape``, ``r`` (within the fold's rows) and ``RMSE``
    (weights 0-1).
    """
    face, d = outcome.face, outcome.face.data
    c = face.config
    y, pred = d.y_norm * d.e, held_out_predictions(face)
    rows = []
    for f, (_, test) in enumerate(cv_folds(d, c.cv, c.n_splits, c.seed, c.max_folds), 1):
        who = ", ".join(sorted(set(d.groups[test]))) if c.cv == "lopo" else f"{len(test)} random rows"
        for b, name in enumerate(face.blendshapes):
            rows.append({"fold": f, "held out": who, "blendshape": name,
                         "r": _r(y[test, b], pred[test, b]), "RMSE": _rmse(y[test, b], pred[test, b])})
    return pd.DataFrame(rows)


def grid_table(outcome: TrainingOutcome) -> pd.DataFrame:
    """The grid search: one row per blendshape and grid point, CV MSE, the chosen point marked."""
    rows = []
    for name, search in outcome.face.search.items():
        for point in search.table:
            chosen = all(point[k] == search.best[k] for k in ("C", "gamma", "epsilon"))
            rows.append({"blendshape": name, "C": point["C"], "gamma": point["gamma"],
                         "epsilon": point["epsilon"], "CV MSE": point["mse"], "chosen": "yes" if chosen else ""})
    return pd.DataFrame(rows)


def grid_edge_warnings(grid: pd.DataFrame) -> list[str]:
    """Blendshapes whose chosen C, gamma or epsilon is the grid's smallest or largest value.

    The best point may then lie outside the grid searched: a wider grid (``paper``) may fit better.

    Parameters
    ----------
    grid : DataFrame
        :func:`grid_table` of a training.

    Returns
    -------
    list of str
        One line per blendshape at an edge, e.g. ``"mouth_open: C 10 is the grid's largest value"``.
    """
    out: list[str] = []
    if grid.empty:
        return out
    for name, rows in grid.groupby("blendshape", sort=False):
        chosen = rows[rows["chosen"] == "yes"]
        if chosen.empty:
            continue
        edges = []
        for k in ("C", "gamma", "epsilon"):
            values = sorted(set(rows[k]))
            value = chosen.iloc[0][k]
            if len(values) > 1 and value in (values[0], values[-1]):
                edges.append(f"{k} {value:g} is the grid's {'smallest' if value == values[0] else 'largest'} value")
        if edges:
            out.append(f"{name}: " + ", ".join(edges))
    return out


def held_out_pairs(outcome: TrainingOutcome) -> dict[str, np.ndarray]:
    """Key-framed and held-out predicted weights (n, B), rows where the key-frames exist."""
    d = outcome.face.data
    return {"measured": d.y_norm * d.e, "predicted": held_out_predictions(outcome.face)}


# --------------------------------------------------------------------------- comparing bundles


def bundle_settings(provenance: dict[str, Any], metrics: dict[str, Any]) -> dict[str, Any]:
    """How a bundle was trained, as Compare shows it: CV scheme, rater policy and source (humans, or
    humans + machine), grid, chosen C/gamma/epsilon.

    Older bundles without a field show ``"not recorded"``.
    """
    cv = provenance.get("cv")
    out: dict[str, Any] = {
        "CV scheme": CV_LABELS.get(str(cv), "not recorded") if cv else "not recorded",
        "rater policy": provenance.get("rater_policy", "not recorded"),
        "rater source": provenance.get("raters", "not recorded"),
        "grid": _grid_name(provenance.get("grid")),
        "participants": provenance.get("n_participants", "not recorded"),
    }
    for name, search in metrics.get("face_cv", {}).items():
        best = search.get("best", {})
        out[f"{name} C / gamma / epsilon"] = " / ".join(f"{best[k]:g}" for k in ("C", "gamma", "epsilon")
                                                       if k in best) or "not recorded"
    return out


def _grid_name(grid: Any) -> str:
    """A grid's name when it is one of :data:`GRIDS`, else its values."""
    if not isinstance(grid, dict):
        return "not recorded"
    name = next((k for k, v in GRIDS.items() if {a: list(b) for a, b in v.items()} == grid), None)
    return name or "; ".join(f"{k} {v}" for k, v in grid.items())


def cv_caption(cv_a: str, cv_b: str) -> str:
    """The caption over two models' stored scores: one scheme named once, two named per model."""
    if cv_a == cv_b:
        return f"Scores stored in each model.json, both by {cv_a} on its own training data:"
    return (f"Scores stored in each model.json: model A by {cv_a}, model B by {cv_b}. The schemes "
            "differ, so the difference column does not compare like with like:")
