"""Re-scoring a model bundle on other data: the one evaluation of ``effortface evaluate`` and
``effortface demo``.

The bundle is loaded through the runtime (:func:`effortface.train.runtime.load_model`), as a game
would load it:

- heart rate: the bundle's training-level regression at each participant's TL, simulated over each
  whole session from its first measured value (r, RMSE in % of the NHR range, HR RMSE in bpm);
- face: the SVRs on the measured [w, p, NHR, EPOC_norm] of each second, times the participant's own
  expressiveness (maximal key-framed weight), clipped, against the key-framed weights (r, RMSE in %
  of the observed range and of [0, 1]).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pandas as pd

from effortface.core.errors import UserError
from effortface.core.fileio import atomic_write_text
from effortface.train.dataset import hr_series, prepare
from effortface.train.face_fit import expressiveness, weight_metrics
from effortface.train.hr_fit import HrCoefficients, score_series, simulate_series
from effortface.train.report import markdown_table

#: the heart-rate columns of the evaluation report
HR_REPORT_COLUMNS = ["participant", "session", "r", "rmse_pct", "hr_rmse_bpm", "n"]


@dataclasses.dataclass
class Evaluation:
    """Scores of a bundle on a data set: per session (heart rate) and per blendshape (face)."""

    hr: pd.DataFrame
    face: pd.DataFrame


def evaluate_bundle(model_dir: str | Path, table: pd.DataFrame, source: str = "table") -> Evaluation:
    """Score a model folder on a long table (see the module docstring).

    Parameters
    ----------
    model_dir : path-like
        The model folder.
    table : DataFrame
        Long table with the bundle's blendshape columns.
    source : str
        Name of the data for error messages.

    Returns
    -------
    Evaluation

    Raises
    ------
    UserError
        If the table lacks one of the model's blendshape columns, or its data are refused by
        :func:`effortface.train.dataset.prepare`.
    """
    from effortface.train.bundle import read_bundle
    from effortface.train.physiology import EpocParams, NhrParams
    from effortface.train.runtime import load_model

    model = load_model(model_dir)
    bundle = read_bundle(model_dir)
    names = list(model.blendshapes.names)
    missing = [n for n in names if n not in table.columns]
    if missing:
        raise UserError(f"{source}: expected the model's blendshape columns {', '.join(missing)}, "
                        f"found {', '.join(table.columns)}")
    prepared = prepare(table, bundle.physiology["hr_max_formula"], EpocParams(**bundle.physiology["epoc"]),
                       source)
    reg = bundle.nhr_regression
    hr_rows = []
    for s in hr_series(prepared):
        coef = HrCoefficients.from_nhr_params(NhrParams.from_training_level(s.training_level, reg))
        hr_rows.append(dataclasses.asdict(score_series(s, simulate_series(s, coef), "tl_regression")))
    e = expressiveness(prepared, names).loc[prepared["participant"]].to_numpy(float)
    x = prepared[["w_per_kg", "p_per_kg", "nhr", "epoc_norm"]].to_numpy(float)
    ok = np.isfinite(x).all(axis=1)
    pred = np.full((len(x), len(names)), np.nan)
    pred[ok] = np.clip(model.face.predict(x[ok]) * e[ok], 0, 1)
    face_rows = [{"blendshape": n, **weight_metrics(prepared[n].to_numpy(float), pred[:, b])}
                 for b, n in enumerate(names)]
    return Evaluation(pd.DataFrame(hr_rows), pd.DataFrame(face_rows))


def evaluation_report(ev: Evaluation, model: str | Path, source: str) -> str:
    """The Markdown report ``effortface evaluate`` prints: headed tables and the mean scores.

    Parameters
    ----------
    ev : Evaluation
        From :func:`evaluate_bundle`.
    model : path-like
        The model folder (the title).
    source : str
        The data it was scored on (the title).

    Returns
    -------
    str
        The report, without a final newline.
    """
    return "\n".join([
        f"# evaluation of {model} on {source}\n",
        "## heart rate (TL regression, simulated over whole sessions)\n",
        markdown_table(ev.hr[HR_REPORT_COLUMNS]),
        f"\nmean: r {ev.hr['r'].mean():.3f}, RMSE {ev.hr['rmse_pct'].mean():.1f} % of the NHR range, "
        f"{ev.hr['hr_rmse_bpm'].mean():.1f} bpm\n",
        "## face (SVR x each participant's expressiveness)\n",
        markdown_table(ev.face),
    ])


def write_evaluation(ev: Evaluation, path: str | Path, model: str | Path, source: str) -> Path:
    """Write every score of an evaluation as a Markdown file (``evaluation.md`` of the demo).

    Parameters
    ----------
    ev : Evaluation
        From :func:`evaluate_bundle`.
    path : path-like
        The file to write (atomically).
    model : path-like
        The model folder (the title).
    source : str
        The data it was scored on (the title).

    Returns
    -------
    Path
        ``path``.
    """
    text = (f"# Evaluation of {model} on {source}\n\n{markdown_table(ev.hr)}\n\n"
            f"{markdown_table(ev.face)}\n")
    return atomic_write_text(path, text)
