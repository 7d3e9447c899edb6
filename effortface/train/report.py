"""The trainer's report: Markdown with PNG plots like the paper's Fig. 2 and Fig. 3, and metric tables.

Figures come from :func:`effortface.core.figures.agg_figure` (Agg canvas, no pyplot), so the Train
stage may write the report from its worker thread.
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from effortface.core.docs import DESIGN, SCIENCE, cite
from effortface.core.figures import agg_figure
from effortface.train.export import hr_warnings
from effortface.train.face_fit import PAPER_FACE_TRAINING_RMSE_PCT, FaceModelFit, training_scores
from effortface.train.game_score import MODEL_MEANINGS, headline
from effortface.train.hr_fit import HELD_OUT_MODELS, PAPER_HR, HrEvaluation, HrSeries
from effortface.synth.physiology import PAPER_REGRESSION

REPORT_MD = "report.md"
FIG2_PNG = "fig2_nhr.png"
FIG3_PNG = "fig3_blendshapes.png"
#: What Fig. 3's rows mean (printed under the figure).
FIG3_PROTOCOLS_TEXT = (
    "same participant exercise: one model per participant and exercise, each fifth of the time "
    "predicted from the other four fifths | unseen participant: trained on everyone else | "
    "unseen exercise: trained on the other exercises, everyone pooled. Predicted weights = "
    "prediction x expressiveness estimated from the training rows only (never the shown key-frames).")
#: at most this many sessions in Fig. 2 (one panel each)
MAX_FIG2_PANELS = 12
_REAL, _PRED, _PRED2 = "#1f77b4", "#d62728", "#ff7f0e"  # the paper's blue (real) and red (predicted)


def plot_fig2(evaluation: HrEvaluation, series: Sequence[HrSeries], path: str | os.PathLike) -> Path:
    """Fig. 2: measured and simulated NHR over time (minutes), one panel per session.

    Each panel shows the measured NHR (blue), the participant's own model fitted on their other
    sessions (orange; held-out time) and the training-level model fitted without that participant
    (red).
    """
    shown = list(series)[:MAX_FIG2_PANELS]
    cols = 3 if len(shown) > 4 else 2 if len(shown) > 1 else 1
    rows = int(np.ceil(len(shown) / cols))
    fig = agg_figure((4.2 * cols, 2.6 * rows), layout="constrained")
    axes = fig.subplots(rows, cols, squeeze=False, sharey=True)
    for ax, s in zip(axes.flat, shown):
        t_min = np.asarray(s.t_s) / 60.0
        ax.plot(t_min, s.nhr, color=_REAL, lw=1.2, label="measured")
        ax.plot(t_min, evaluation.predictions[("per_participant", s.session)], color=_PRED2, lw=1,
                label="own model (other sessions)")
        ax.plot(t_min, evaluation.predictions[("tl_regression", s.session)], color=_PRED, lw=1,
                ls="--", label="TL model (held out)")
        ax.set_title(f"{s.participant} TL {s.training_level:.3g}: {s.session.split('_')[-1]}", fontsize=9)
        ax.set_ylim(-0.05, 1.05)
        ax.set_xlabel("time (min)", fontsize=8)
        ax.set_ylabel("NHR", fontsize=8)
        ax.tick_params(labelsize=7)
    for ax in list(axes.flat)[len(shown):]:
        ax.set_visible(False)
    axes.flat[0].legend(fontsize=7, loc="upper left")
    fig.suptitle("Fig. 2: measured and simulated normalised heart rate", fontsize=11)
    fig.savefig(path, dpi=110)
    return Path(path)


def plot_fig3(fit: FaceModelFit, predictions: Mapping[str, np.ndarray], path: str | os.PathLike,
              session: str | None = None) -> Path:
    """Fig. 3: key-framed (blue) and predicted (red) weights of one session, per protocol and blendshape.

    ``predictions`` is :func:`effortface.train.face_fit.protocol_scores`' second value. The session defaults to
    the one with the most varied annotations.
    """
    d = fit.data
    session = session or _liveliest_session(fit)
    rows = np.flatnonzero(d.session == session)
    rows = rows[np.argsort(d.t_s[rows])]
    protos = [p for p in predictions if np.isfinite(predictions[p][rows]).any()]
    nb = len(fit.blendshapes)
    fig = agg_figure((3.3 * nb, 2.3 * max(len(protos), 1)), layout="constrained")
    axes = fig.subplots(max(len(protos), 1), nb, squeeze=False, sharex=True, sharey=True)
    t_min = d.t_s[rows] / 60.0
    for i, proto in enumerate(protos):
        for b, name in enumerate(fit.blendshapes):
            ax = axes[i, b]
            ax.plot(t_min, d.y_norm[rows, b] * d.e[rows, b], color=_REAL, lw=1.2, label="key-framed")
            ax.plot(t_min, predictions[proto][rows, b], color=_PRED, lw=1, label="predicted")
            ax.set_ylim(-0.02, 1.02)
            ax.tick_params(labelsize=7)
            if i == 0:
                ax.set_title(name, fontsize=9)
            if b == 0:
                ax.set_ylabel(proto.replace("_", " "), fontsize=8)
            if i == len(protos) - 1:
                ax.set_xlabel("time (min)", fontsize=8)
    axes[0, 0].legend(fontsize=7, loc="upper left")
    fig.suptitle(f"Fig. 3: blendshape weights of {session} (never in the model's training data)",
                 fontsize=11)
    fig.text(0.5, 0.0, FIG3_PROTOCOLS_TEXT, ha="center", va="bottom", fontsize=7, wrap=True)
    fig.get_layout_engine().set(rect=(0, 0.06, 1, 0.94))
    fig.savefig(path, dpi=110)
    return Path(path)


def _liveliest_session(fit: FaceModelFit) -> str:
    """The session whose annotated weights vary most (the most telling plot)."""
    d = fit.data
    weights = pd.DataFrame(d.y_norm * d.e)
    spread = {s: float(np.nanstd(w.to_numpy())) for s, w in weights.groupby(d.session, sort=True)}
    return max(spread, key=spread.__getitem__)


def markdown_table(df: pd.DataFrame) -> str:
    """A DataFrame as a Markdown table (floats to 3 significant digits)."""
    cols = list(df.columns)
    out = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for _, row in df.iterrows():
        out.append("| " + " | ".join(f"{v:.3g}" if isinstance(v, float) else str(v) for v in row) + " |")
    return "\n".join(out)


def write_report(folder: str | os.PathLike, *, evaluation: HrEvaluation, series: Sequence[HrSeries],
                 fit: FaceModelFit, held_out: pd.DataFrame, protocols: pd.DataFrame,
                 protocol_predictions: Mapping[str, np.ndarray],
                 header: Mapping[str, Any] | None = None,
                 label_comparison: pd.DataFrame | str | None = None) -> Path:
    """Write ``report.md`` with ``fig2_nhr.png`` and ``fig3_blendshapes.png`` into ``folder``.

    Parameters
    ----------
    folder : path-like
        Output folder (created); existing report files in it are replaced.
    evaluation, series
        Heart-rate evaluation and the sessions it scored.
    fit, held_out, protocols, protocol_predictions
        Face fit, its held-out scores, the Fig. 3 protocol scores and predictions.
    header : mapping, optional
        Lines of provenance (``key: value``) for the top of the report.
    label_comparison : DataFrame or str, optional
        ``--raters humans+machine``: held-out scores on human labels of a fit on human labels only and
        of this fit (:func:`effortface.train.rater_sources.label_comparison`), or why there is none.

    Returns
    -------
    Path
        The report file.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    plot_fig2(evaluation, series, folder / FIG2_PNG)
    plot_fig3(fit, protocol_predictions, folder / FIG3_PNG)
    text = "\n".join([*_report_lines(evaluation, fit, held_out, protocols, header or {}),
                      *label_comparison_lines(label_comparison)])
    path = folder / REPORT_MD
    path.write_text(text, encoding="utf-8")
    return path


def _report_lines(evaluation: HrEvaluation, fit: FaceModelFit, held_out: pd.DataFrame,
                  protocols: pd.DataFrame, header: Mapping[str, Any]) -> list[str]:
    """The Markdown body."""
    coef = pd.DataFrame([{"participant": p, "training_level": evaluation.fit.training_levels[p],
                          **c.as_dict()} for p, c in evaluation.fit.per_participant.items()])
    reg = pd.DataFrame([{"coefficient": k, **v, "paper intercept": getattr(PAPER_REGRESSION, k)[0],
                         "paper slope": getattr(PAPER_REGRESSION, k)[1]}
                        for k, v in evaluation.fit.tl_regression.as_dict().items()])
    best = pd.DataFrame([{"blendshape": b, **s.best, "cv_mse": s.cv_mse, "cv_r": s.cv_r}
                         for b, s in fit.search.items()])
    mean_scores = held_out.groupby("model", sort=False)[["r", "rmse_pct_range", "rmse_pct_unit"]].mean()
    in_sample = training_scores(fit)
    return [
        "# effortface training report", "",
        *[f"- {k}: {v}" for k, v in header.items()], "",
        f"The science behind these figures: {cite(SCIENCE)}; the formats: {cite(DESIGN)}.", "",
        f"## Heart rate ({SCIENCE} section 3)", "",
        "Simulated over whole sessions from the first measured value. RMSE in % of the NHR range [0, 1]. "
        f"Held out (scored on data the model was not fitted on): {', '.join(HELD_OUT_MODELS)}. "
        "per_participant is the participant's own tree fitted on their other sessions (or the other "
        "half of a single session); per_participant_in_sample is fitted and scored on the same "
        "sessions (the paper's protocol for its per-participant figure); pooled_threshold is one "
        "threshold tree fitted on everyone else without training level - not the paper's pooled "
        "model (an unpruned regression tree), so its paper figure is only indicative; tl_regression "
        "is fitted without the scored participant.", "",
        markdown_table(_hr_table(evaluation)), "", *hr_warnings(evaluation.summary()), "",
        "Per-participant trees (fitted on all their sessions):", "", markdown_table(coef), "",
        "Regressions on training level (value = intercept + slope x TL), beside the paper's "
        "(Boukhalfi et al. 2015; t_root in W/kg, c_inc and c_dec per second):", "", markdown_table(reg), "",
        f"![Fig. 2]({FIG2_PNG})", "",
        f"## Face ({SCIENCE} section 5)", "",
        f"Hyper-parameters by {fit.config.cv} cross-validation over C {fit.config.grid['C']}, "
        f"gamma {fit.config.grid['gamma']}, epsilon {fit.config.grid['epsilon']}:", "", markdown_table(best), "",
        *_headline_lines(held_out),
        "Held-out participants (weights = prediction x an expressiveness estimated without the "
        "scored participant's key-frames: the training participants' mean, except "
        "svr_known_expressiveness). What each row is:", "",
        *[f"- {m}: {MODEL_MEANINGS[m]}" for m in held_out["model"].unique() if m in MODEL_MEANINGS], "",
        markdown_table(held_out), "",
        "Mean over blendshapes:", "", markdown_table(mean_scores.reset_index()), "",
        "In-sample (the final SVRs on their own training rows) beside the paper's training RMSE of "
        f"{PAPER_FACE_TRAINING_RMSE_PCT[0]:g}-{PAPER_FACE_TRAINING_RMSE_PCT[1]:g} % (also in-sample):", "",
        markdown_table(in_sample), "",
        "The paper's Fig. 3 protocols (no label of the predicted rows is used):", "", markdown_table(protocols), "",
        f"![Fig. 3]({FIG3_PNG})", "", FIG3_PROTOCOLS_TEXT, "",
        "Expressiveness (maximal key-framed weight per participant):", "",
        markdown_table(fit.expressiveness.reset_index()), "",
    ]


def label_comparison_lines(comparison: pd.DataFrame | str | None) -> list[str]:
    """The report's section "Human labels only against human + machine labels" (nothing for None)."""
    if comparison is None:
        return []
    head = ["## Human labels only against human + machine labels (--raters humans+machine)", "",
            "The machine (machine/face_landmarker.csv, effortface preannotate) labels only the seconds no "
            "human keyed. The face models were fitted twice, on the human labels only and on human + machine "
            "labels; both are scored out of fold on the held-out participants' **human** labels only.", ""]
    if isinstance(comparison, str):
        return [*head, f"No comparison: {comparison}.", ""]
    return [*head, markdown_table(comparison), ""]
def _headline_lines(held_out: pd.DataFrame) -> list[str]:
    """The face score the report leads with, labelled, and the measured-NHR score beside it."""
    model, r, rmse = headline(held_out)
    label = "as a game uses it" if model == "svr_as_game" else "with measured NHR"
    lines = [f"**Held-out face score {label}: mean r {r:.3f}, RMSE {rmse:.1f} % of the range** ({model}: "
             f"{MODEL_MEANINGS[model]}).", ""]
    measured = held_out[held_out["model"] == "svr"]
    if model != "svr" and len(measured):
        lines += [f"With the measured NHR (svr, what a game never has): mean r {measured['r'].mean():.3f}, "
                  f"RMSE {measured['rmse_pct_range'].mean():.1f} % of the range.", ""]
    return lines


def _hr_table(evaluation: HrEvaluation) -> pd.DataFrame:
    """Heart-rate scores per model, marked held out or in-sample, beside the paper's figures."""
    return pd.DataFrame([{"model": k, "scored on": "held out" if k in HELD_OUT_MODELS else "in-sample",
                          **v, "paper r": PAPER_HR.get(k, {}).get("r", np.nan),
                          "paper RMSE %": PAPER_HR.get(k, {}).get("rmse_pct", np.nan)}
                         for k, v in evaluation.summary().items()])
