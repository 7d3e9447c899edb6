"""Re-scoring a model bundle on other data: the one evaluation of ``effortface evaluate`` and
``effortface demo``.

The bundle is loaded through the runtime (:func:`effortface.synth.runtime.load_model`), as a game
would load it:

- heart rate: the bundle's training-level regression at each participant's TL, simulated over each
  whole session from its first measured value (r, RMSE in % of the NHR range, HR RMSE in bpm);
- face, as a game uses it (the headline): the SVRs on [w, p, NHR, EPOC_norm] with NHR and EPOC
  simulated from each session's work from rest by the bundle's heart-rate model at the participant's
  training level (no measured heart rate), and beside it the same SVRs on the measured NHR and EPOC;
  against the key-framed weights (r, RMSE in % of the observed range and of [0, 1]).
- scaling: predictions are normalised weights; by default they are multiplied by the mean
  expressiveness of the bundle's training participants (model.json metrics; 1, the runtime's default
  character, for a bundle without them), never by the scored participants' key-frames.
  ``known_expressiveness=True`` (``--known-expressiveness``) multiplies by each scored participant's
  own maximal key-framed weight instead: it borrows from the labels it is scored against, and the
  report says so.
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
    face_measured_nhr: pd.DataFrame = dataclasses.field(default_factory=pd.DataFrame)
    scaling: str = ""


def evaluate_bundle(model_dir: str | Path, table: pd.DataFrame, source: str = "table", *,
                    known_expressiveness: bool = False) -> Evaluation:
    """Score a model folder on a long table (see the module docstring).

    Parameters
    ----------
    model_dir : path-like
        The model folder.
    table : DataFrame
        Long table with the bundle's blendshape columns.
    source : str
        Name of the data for error messages.
    known_expressiveness : bool
        Multiply by each scored participant's own maximal key-framed weight (borrows from the
        labels) instead of the training participants' mean expressiveness.

    Returns
    -------
    Evaluation

    Raises
    ------
    UserError
        If the table lacks one of the model's blendshape columns, or its data are refused by
        :func:`effortface.train.dataset.prepare`.
    """
    from effortface.synth.bundle import read_bundle
    from effortface.synth.physiology import EpocParams, NhrParams
    from effortface.synth.runtime import load_model

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
    e, scaling = _scaling(prepared, names, bundle.metrics, known_expressiveness)
    measured = prepared[["w_per_kg", "p_per_kg", "nhr", "epoc_norm"]].to_numpy(float)
    game = _game_features(prepared, measured, reg, bundle.physiology)
    faces = []
    for x in (game, measured):
        ok = np.isfinite(x).all(axis=1) & np.isfinite(measured).all(axis=1)  # the same seconds
        pred = np.full((len(x), len(names)), np.nan)
        pred[ok] = np.clip(model.face.predict(x[ok]) * e[ok], 0, 1)
        faces.append(pd.DataFrame([{"blendshape": n, **weight_metrics(prepared[n].to_numpy(float), pred[:, b])}
                                   for b, n in enumerate(names)]))
    return Evaluation(pd.DataFrame(hr_rows), faces[0], faces[1], scaling)


def _scaling(prepared: pd.DataFrame, names: list[str], metrics: dict, known: bool
             ) -> tuple[np.ndarray, str]:
    """Per row the expressiveness predictions are multiplied by, and a sentence saying which."""
    if known:
        e = expressiveness(prepared, names).loc[prepared["participant"]].to_numpy(float)
        return e, ("each scored participant's own maximal key-framed weight (--known-expressiveness: "
                   "borrows from the labels it is scored against)")
    trained = pd.DataFrame(metrics.get("expressiveness") or {}).T
    if set(names) <= set(trained.columns) and len(trained):
        mean = trained[names].astype(float).mean().to_numpy()
        text = (f"the mean expressiveness of the model's {len(trained)} training participants "
                f"({', '.join(f'{n} {v:.2f}' for n, v in zip(names, mean))}); no key-frame of the scored data")
    else:
        mean = np.ones(len(names))
        text = "1 (the runtime's default character; the bundle stores no training expressiveness)"
    return np.broadcast_to(mean, (len(prepared), len(names))), text


def _game_features(prepared: pd.DataFrame, measured: np.ndarray, regression: object,
                   physiology: dict) -> np.ndarray:
    """[w, p, NHR, EPOC_norm] with NHR and EPOC simulated from each session's work from rest by
    the bundle's heart-rate model (:func:`effortface.train.game_score.simulated_features`)."""
    from effortface.train.game_score import simulated_features
    from effortface.synth.physiology import EpocParams

    x = measured.copy()
    epoc = EpocParams(**physiology["epoc"])
    for s, (_, rows) in zip(hr_series(prepared), prepared.groupby("session", sort=False, observed=True)):
        nhr, epoc_norm = simulated_features(s, rows.iloc[0], regression, epoc, physiology["hr_max_formula"])
        at = prepared.index.get_indexer(rows.index)
        x[at, 2], x[at, 3] = nhr, epoc_norm
    return x


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
        f"Scaling: predictions x {ev.scaling or 'each participant expressiveness'}.\n",
        "## face as a game uses it (NHR and EPOC simulated from work by the bundle's heart model, "
        "no measured heart rate)\n",
        markdown_table(ev.face),
        *(["\n## face with the measured NHR and EPOC (a game never has them)\n",
           markdown_table(ev.face_measured_nhr)] if len(ev.face_measured_nhr) else []),
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
    text = evaluation_report(ev, model, source) + "\n"
    return atomic_write_text(path, text)
