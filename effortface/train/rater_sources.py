"""``--raters humans+machine``: what the machine's labels change, scored on the humans' labels.

With ``humans+machine`` the training table carries ``machine_<blendshape>`` columns (True where the
label is the machine's: no human keyed that second, :mod:`effortface.train.dataset`). The comparison
fits the face models a second time on the humans' labels only (the machine's set to empty), then
scores both fits' out-of-fold SVR predictions against the **human** labels of the held-out
participants only: the same question for both, "how well are the humans' key-frames predicted?".
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence

import numpy as np
import pandas as pd

from effortface.core.blendshapes import BlendshapeSet
from effortface.core.errors import UserError
from effortface.train.dataset import MACHINE_PREFIX
from effortface.train.face_fit import FaceModelFit, _fold_expressiveness, weight_metrics

#: the two label sets compared, in the report's order
LABEL_SETS = ("humans", "humans+machine")


def machine_columns(table: pd.DataFrame, blendshapes: Sequence[str]) -> list[str]:
    """The ``machine_<blendshape>`` columns present in ``table``."""
    return [MACHINE_PREFIX + b for b in blendshapes if MACHINE_PREFIX + b in table]


def machine_label_counts(table: pd.DataFrame, blendshapes: Sequence[str]) -> dict[str, int]:
    """Per blendshape, the seconds labelled by the machine (0 without the columns)."""
    return {b: int(table[MACHINE_PREFIX + b].sum()) if MACHINE_PREFIX + b in table else 0 for b in blendshapes}


def humans_only(table: pd.DataFrame, blendshapes: Sequence[str]) -> pd.DataFrame:
    """A copy of the table with the machine's labels emptied (NaN) and the ``machine_*`` columns dropped."""
    out = table.copy()
    for b in blendshapes:
        col = MACHINE_PREFIX + b
        if col in out:
            out.loc[out[col].astype(bool), b] = np.nan
    return out.drop(columns=machine_columns(table, blendshapes))


def _human_mask(fit: FaceModelFit, table: pd.DataFrame) -> np.ndarray:
    """(n rows of the fit, B): True where the fit's row has a human label (looked up by session and t_s)."""
    cols = [MACHINE_PREFIX + b for b in fit.blendshapes]
    if not all(c in table for c in cols):
        return np.ones((len(fit.data.t_s), len(fit.blendshapes)), bool)
    flags = table.set_index(["session", "t_s"])[cols].astype(bool)
    keys = pd.MultiIndex.from_arrays([fit.data.session, fit.data.t_s])
    return ~flags.reindex(keys).fillna(False).to_numpy(bool)


def held_out_on_human_labels(fit: FaceModelFit, table: pd.DataFrame) -> list[dict[str, object]]:
    """The SVR's out-of-fold scores (weight scale, expressiveness estimated without the held-out
    participant) against the human labels only, per blendshape."""
    e_est = _fold_expressiveness(fit, False)
    human = _human_mask(fit, table)
    rows = []
    for b, name in enumerate(fit.blendshapes):
        y = fit.data.y_norm[:, b] * fit.data.e[:, b]
        y = np.where(human[:, b], y, np.nan)
        pred = np.clip(fit.search[name].oof * e_est[:, b], 0, 1)
        rows.append({"blendshape": name, **weight_metrics(y, pred)})
    return rows


def label_comparison(fit_humans: FaceModelFit, table_humans: pd.DataFrame, fit_both: FaceModelFit,
                     table_both: pd.DataFrame) -> pd.DataFrame:
    """Held-out SVR scores on the human labels of a fit on human labels only and of one on human + machine.

    Returns
    -------
    DataFrame
        Columns ``blendshape, labels, r, rmse_pct_range, rmse_pct_unit, n, machine_seconds``; ``labels`` is
        one of :data:`LABEL_SETS`; ``machine_seconds`` the seconds the machine labelled (training table).
    """
    counts = machine_label_counts(table_both, fit_both.blendshapes)
    rows: list[dict[str, object]] = []
    for labels, fit, table in (("humans", fit_humans, table_humans), ("humans+machine", fit_both, table_both)):
        for r in held_out_on_human_labels(fit, table):
            name = str(r["blendshape"])
            rows.append({**r, "blendshape": name, "labels": labels,
                         "machine_seconds": counts[name] if labels == "humans+machine" else 0})
    return pd.DataFrame(rows)



def machine_agreement(folders: Sequence[str | os.PathLike], blendshapes: BlendshapeSet,
                      rater_policy: str = "mean") -> list[dict[str, object]]:
    """The machine rater's agreement with the humans on the training sessions, per blendshape.

    At every second of a session where the humans' label exists (their key-frames under the rater
    policy, interpolated as for training) and the machine found a face, the pair (machine weight,
    human label) is kept; the figures are over all such pairs of all sessions.

    Parameters
    ----------
    folders : sequence of path-like
        Session folders, or folders of sessions (as given to training).
    blendshapes : BlendshapeSet
    rater_policy : str
        ``"mean"`` (the humans' mean) or one rater's name.

    Returns
    -------
    list of dict
        ``blendshape, n, icc_a1, icc_a1_ci_low, icc_a1_ci_high, r, mad_pct``; NaN where fewer than
        three pairs exist (or the blendshape is not one the machine rates).
    """
    from effortface.annotate.agreement import icc_a1, icc_a1_ci
    from effortface.annotate.machine.track import FOUR, read_machine_track
    from effortface.core.session.folder import check_session
    from effortface.train.dataset import _nearest_frames, _weights, expand_paths

    pairs: dict[str, list[np.ndarray]] = {b: [] for b in blendshapes.names}
    for folder in expand_paths(folders):
        s = check_session(folder)
        track = read_machine_track(s.path)
        if track is None or track.t_s.size < 2 or not s.frame_times_s:
            continue
        t = np.arange(0.0, math.floor(s.frame_times_s[-1]) + 1.0)
        try:
            human = _weights(s, t, blendshapes, rater_policy, machine=True)
        except UserError:
            continue
        idx = _nearest_frames(np.asarray(track.t_s, float), t)
        for j, name in enumerate(blendshapes.names):
            if name in FOUR:
                machine = np.clip(track.weights[idx, FOUR.index(name)], 0.0, 1.0)
                ok = np.isfinite(machine) & np.isfinite(human[:, j])
                pairs[name].append(np.column_stack([machine[ok], human[ok, j]]))
    rows: list[dict[str, object]] = []
    for name, parts in pairs.items():
        x = np.concatenate(parts) if parts else np.empty((0, 2))
        row: dict[str, object] = {"blendshape": name, "n": int(len(x)), "icc_a1": math.nan,
                                  "icc_a1_ci_low": math.nan, "icc_a1_ci_high": math.nan,
                                  "r": math.nan, "mad_pct": math.nan}
        if len(x) >= 3 and np.ptp(x, axis=0).min() > 0:
            low, high = icc_a1_ci(x)
            row.update(icc_a1=icc_a1(x), icc_a1_ci_low=low, icc_a1_ci_high=high,
                       r=float(np.corrcoef(x[:, 0], x[:, 1])[0, 1]),
                       mad_pct=100.0 * float(np.mean(np.abs(x[:, 0] - x[:, 1]))))
        rows.append(row)
    return rows
