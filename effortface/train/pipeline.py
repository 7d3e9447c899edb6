"""The one training run, shared by ``effortface train``, ``effortface demo`` and the Train stage.

- :func:`training_table` reads the data (sessions or a long table);
- :func:`train_models` checks and prepares them, then fits and scores both models (the paper's
  heart-rate models, the four face SVRs and their held-out and Fig. 3 protocol scores), reporting
  progress and stopping at a cancel check between steps and cross-validation folds; it writes
  nothing and returns a :class:`TrainingOutcome`;
- :func:`export_outcome` writes the bundle (effortface/train/export.py: ``model.json``, ``svr.npz``,
  ``face.onnx`` with its parity checks, ``MODEL_CARD.md``) and the report (effortface/train/report.py);
- :func:`run_training` is both, with progress bars on stderr (the command line).

The command line and the GUI call these functions; neither repeats a step.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import math
import shutil
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from effortface.annotate.completeness import RULE_TEXT as ANNOTATION_RULE
from effortface.core.progress import ProgressBar
from effortface.core.jobs import Cancelled  # noqa: F401  (re-exported: the one cancel exception)
from effortface.core.blendshapes import BlendshapeSet
from effortface.core.errors import UserError
from effortface.core.version import __version__
from effortface.train.dataset import check_raters, hr_series, prepare, read_table, sessions_table
from effortface.train.face_fit import (GRIDS, MIN_ROWS_PER_PARTICIPANT, FaceFitConfig, FaceModelFit,
                                       check_face_table, fit_face_models, held_out_scores,
                                       protocol_scores, training_scores)
from effortface.train.game_score import game_scores
from effortface.train.hr_fit import PAPER_HR, HrEvaluation, HrSeries, check_hr_series, evaluate_hr_models
from effortface.synth.parallel import ComputeSettings, compute_backend

REPORT_DIR = "report"
#: fraction of the progress reached after each step of :func:`train_models` (the CV folds fill the middle)
_STEP_FRACTION = {"prepare": 0.05, "hr": 0.2, "folds": 0.8, "held_out": 0.85, "protocols": 1.0}

#: ``progress(fraction, text)``: fraction of the run done (0-1) and what runs now
ProgressFn = Callable[[float, str], None]


def _no_progress(fraction: float, text: str) -> None:
    """A progress callback that shows nothing."""


def _never() -> bool:
    """A cancel check that never cancels."""
    return False


# --------------------------------------------------------------------------- settings and data


@dataclasses.dataclass(frozen=True)
class TrainSettings:
    """The trainer's choices (the options of ``effortface train`` and the Train stage's panel).

    Parameters
    ----------
    rater_policy : str
        ``"mean"`` of the raters or one rater's name.
    raters : {"humans", "humans+machine"}
        Who labels the face: the humans' key-frames only (default), or also the machine track
        where no human keyed (:mod:`effortface.train.dataset`); then the report compares the
        held-out scores of a fit on the humans' labels only with those of this fit.
    grid : str
        A key of :data:`effortface.train.face_fit.GRIDS`.
    cv : {"lopo", "kfold"}
        Leave-one-participant-out (the paper's honest protocol) or random-frame K-fold.
    max_rows_per_participant : int
        Face training rows per participant (1 Hz, evenly spaced; default 3,600 = one hour, i.e.
        every annotated second of most labs). Above
        :data:`~effortface.train.face_fit.EXACT_MAX_ROWS` face rows the fit switches to the
        Nystroem approximation by itself.
    workers : int or None
        Run the CV folds on a local Dask cluster of this many worker processes.
    scheduler : str or None
        Run the CV folds on the Dask scheduler at this address.
    c_values, gamma_values : tuple of float, optional
        Replace the grid's values of C or gamma (``--C``, ``--gamma``); every value positive.
    """

    rater_policy: str = "mean"
    raters: str = "humans"
    grid: str = "small"
    cv: str = "lopo"
    max_rows_per_participant: int = FaceFitConfig().max_rows_per_participant
    workers: int | None = None
    scheduler: str | None = None
    c_values: tuple[float, ...] | None = None
    gamma_values: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        if self.grid not in GRIDS:
            raise UserError(f"grid: expected one of {', '.join(GRIDS)}, found {self.grid!r}")
        for option, values in (("--C", self.c_values), ("--gamma", self.gamma_values)):
            if values is not None and not (values and all(math.isfinite(v) and v > 0 for v in values)):
                raise UserError(f"{option}: expected one or more positive numbers, found "
                                f"{' '.join(f'{v:g}' for v in values) or 'none'}")
        if self.max_rows_per_participant < MIN_ROWS_PER_PARTICIPANT:
            raise UserError(f"max rows per participant: expected at least {MIN_ROWS_PER_PARTICIPANT}, "
                            f"found {self.max_rows_per_participant}")
        if not self.rater_policy.strip():
            raise UserError("rater policy: expected 'mean' or a rater's name, found nothing")
        check_raters(self.raters)
        self.compute()  # checks --workers / --scheduler

    def compute(self) -> ComputeSettings:
        """Where the folds run (:mod:`effortface.synth.parallel`)."""
        return ComputeSettings(self.workers, self.scheduler)

    def config(self) -> FaceFitConfig:
        """The face-fit configuration of these settings."""
        return FaceFitConfig(grid=self.grid_values(), cv=self.cv,
                             max_rows_per_participant=self.max_rows_per_participant)

    def grid_values(self) -> dict[str, list[float]]:
        """The searched values: the named grid with ``c_values`` / ``gamma_values`` put in."""
        grid = dict(GRIDS[self.grid])
        if self.c_values is not None:
            grid["C"] = [float(v) for v in self.c_values]
        if self.gamma_values is not None:
            grid["gamma"] = [float(v) for v in self.gamma_values]
        return grid


def training_table(sessions: Sequence[str | Path], table: str | Path | None, blendshapes: BlendshapeSet,
                   rater_policy: str = "mean", raters: str = "humans") -> tuple[pd.DataFrame, list[str]]:
    """The long training table of some sessions or of a table file, and its source names.

    Parameters
    ----------
    sessions : sequence of path-like
        Session folders, or folders of sessions (used when ``table`` is None).
    table : path-like or None
        A long table CSV (docs/DESIGN.md) instead of sessions.
    blendshapes : BlendshapeSet
        The blendshape set (the table's columns).
    rater_policy : str
        ``"mean"`` of the raters or one rater's key-frames (sessions only).
    raters : {"humans", "humans+machine"}
        Also the machine track's labels where no human keyed (sessions only).

    Returns
    -------
    table : DataFrame
        The long table.
    sources : list of str
        The table file, or the session folders (provenance and messages).
    """
    if table is not None:
        if check_raters(raters) != "humans":
            raise UserError(f"--raters {raters}: expected session folders (a table holds no machine track), "
                            f"found --table {table}")
        return read_table(table, blendshapes), [str(table)]
    return sessions_table(sessions, blendshapes, rater_policy, raters), [str(p) for p in sessions]


def check_training_data(table: pd.DataFrame, blendshapes: BlendshapeSet, source: str,
                        config: FaceFitConfig) -> tuple[pd.DataFrame, list[HrSeries]]:
    """Prepare the table and refuse data the models cannot be fitted on, before any progress shows.

    Parameters
    ----------
    table : DataFrame
        Long training table.
    blendshapes : BlendshapeSet
        The blendshape set.
    source : str
        The table or sessions, for messages.
    config : FaceFitConfig
        Face-fit settings (its subsampling).

    Returns
    -------
    prepared : DataFrame
        From :func:`effortface.train.dataset.prepare`.
    series : list of HrSeries
        From :func:`effortface.train.dataset.hr_series`.

    Raises
    ------
    UserError
        One line naming the source and what is missing (participants, heart rate, annotations).
    """
    prepared = prepare(table, source=source)
    series = hr_series(prepared)
    check_hr_series(series, source)
    check_face_table(prepared, blendshapes.names, source, config)
    return prepared, series


# --------------------------------------------------------------------------- the training run


@dataclasses.dataclass
class TrainingOutcome:
    """Everything a training run produced, for the plots, the tables and the export."""

    prepared: pd.DataFrame
    series: list[HrSeries]
    hr_eval: HrEvaluation
    face: FaceModelFit
    held_out: pd.DataFrame
    protocols: pd.DataFrame
    protocol_predictions: dict[str, np.ndarray]
    blendshapes: BlendshapeSet
    sources: list[str]
    settings: TrainSettings
    #: ``--raters humans+machine``: held-out scores on human labels of both label sets (rater_sources)
    label_comparison: pd.DataFrame | None = None
    #: why there is no comparison (e.g. the machine labelled no second)
    label_note: str = ""
    #: sessions left out (only keys accepted from the machine) and seconds of rater labels by key origin
    label_origins: dict[str, Any] = dataclasses.field(default_factory=dict)

    @property
    def sessions(self) -> list[str]:
        """Session ids scored by the heart-rate evaluation, in order."""
        return [s.session for s in self.series]

    def fig2(self, session: str) -> dict[str, Any]:
        """Fig. 2 curves of one session: ``t_min``, ``measured``, ``own`` and ``tl`` NHR, and a title."""
        s = next(x for x in self.series if x.session == session)
        p = self.hr_eval.predictions
        return {"t_min": np.asarray(s.t_s) / 60.0, "measured": np.asarray(s.nhr, float),
                "own": p[("per_participant", session)], "tl": p[("tl_regression", session)],
                "title": f"{s.participant} (TL {s.training_level:g}): {session}"}

    def fig3(self, session: str, protocol: str) -> dict[str, Any]:
        """Fig. 3 curves: ``t_min``, ``keyed`` (n, B) and ``predicted`` (n, B) of one session."""
        d = self.face.data
        rows = np.flatnonzero(d.session == session)
        rows = rows[np.argsort(d.t_s[rows])]
        return {"t_min": d.t_s[rows] / 60.0, "keyed": d.y_norm[rows] * d.e[rows],
                "predicted": self.protocol_predictions[protocol][rows]}

    def face_sessions(self) -> list[str]:
        """Sessions with face rows (Fig. 3 choices)."""
        return sorted(np.unique(self.face.data.session).tolist())

    def hr_table(self) -> pd.DataFrame:
        """Heart-rate models (held out) beside the paper's figures."""
        rows = [{"model": k, "r": v["r"], "RMSE %": v["rmse_pct"], "HR RMSE bpm": v["hr_rmse_bpm"],
                 "paper r": PAPER_HR.get(k, {}).get("r", np.nan),
                 "paper RMSE %": PAPER_HR.get(k, {}).get("rmse_pct", np.nan)}
                for k, v in self.hr_eval.summary().items()]
        return pd.DataFrame(rows)

    def face_table(self) -> pd.DataFrame:
        """Face held-out scores per blendshape and mean: the SVR as a game uses it (NHR from work)
        and on measured NHR (r and RMSE %), and the linear and mean baselines (r; their RMSE is in
        the report)."""
        wide = self.held_out.pivot_table(index="blendshape", columns="model", values="r", sort=False)
        rmse = self.held_out.pivot_table(index="blendshape", columns="model", values="rmse_pct_range",
                                         sort=False)
        out = pd.DataFrame({"blendshape": wide.index})
        for model, label, with_rmse in (("svr_as_game", "as a game", True), ("svr", "measured NHR", True),
                                        ("linear", "linear", False), ("mean", "mean", False)):
            if model in wide:
                out[f"{label} r"] = wide[model].to_numpy()
                if with_rmse:
                    out[f"{label} RMSE %"] = rmse[model].to_numpy()
        mean = out.drop(columns="blendshape").mean()
        return pd.concat([out, pd.DataFrame([{"blendshape": "mean", **mean}])], ignore_index=True)


def train_models(table: pd.DataFrame, blendshapes: BlendshapeSet, settings: TrainSettings,
                 sources: Sequence[str], progress: ProgressFn = _no_progress,
                 cancelled: Callable[[], bool] = _never) -> TrainingOutcome:
    """Check the data, then fit and score both models (the one training run; writes nothing).

    Parameters
    ----------
    table : DataFrame
        Long training table (:func:`training_table`).
    blendshapes : BlendshapeSet
        The blendshape set.
    settings : TrainSettings
        Rater policy (provenance only here), grid, CV, subsampling.
    sources : sequence of str
        Where the data came from (provenance and messages).
    progress : callable
        ``progress(fraction, text)`` after each step and each CV fold (called from this thread),
        never before the data checks have passed.
    cancelled : callable
        Polled between steps and folds; when it returns True, :class:`Cancelled` is raised.

    Returns
    -------
    TrainingOutcome

    Raises
    ------
    UserError
        Data the models cannot be fitted on (:func:`check_training_data`).
    Cancelled
        When ``cancelled()`` turned True.
    """
    config = settings.config()

    def step(name: str, text: str) -> None:
        if cancelled():
            raise Cancelled(text)
        progress(_STEP_FRACTION[name], text)

    prepared, series = check_training_data(table, blendshapes, ", ".join(sources) or "table", config)
    step("prepare", "heart-rate models")
    hr_eval = evaluate_hr_models(series)
    step("hr", "face SVR grid search")
    with compute_backend(settings.compute()):
        face = _fit_face(prepared, blendshapes, config, cancelled, progress)
        step("folds", "held-out scores")
        game, _ = game_scores(face, series, prepared)
        held = pd.concat([game, held_out_scores(face)], ignore_index=True)
        step("held_out", "the paper's Fig. 3 protocols")
        protos, proto_preds = protocol_scores(face)
    comparison, note = (_label_comparison(table, blendshapes, config, face, settings, cancelled, progress)
                        if settings.raters == "humans+machine" else (None, ""))
    step("protocols", "done")
    return TrainingOutcome(prepared, series, hr_eval, face, held, protos, proto_preds, blendshapes,
                           list(sources), settings, comparison, note, label_origins(table))


def _label_comparison(table: pd.DataFrame, blendshapes: BlendshapeSet, config: FaceFitConfig,
                      face: FaceModelFit, settings: TrainSettings, cancelled: Callable[[], bool],
                      progress: ProgressFn) -> tuple[pd.DataFrame | None, str]:
    """Fit the face on the humans' labels only and compare held-out scores on human labels
    (:mod:`effortface.train.rater_sources`); (None, why) when there is nothing to compare."""
    from effortface.train.rater_sources import humans_only, label_comparison, machine_label_counts

    if sum(machine_label_counts(table, blendshapes.names).values()) == 0:
        return None, "the machine labelled no second (every second had a human label, or no machine track)"
    humans = humans_only(table, blendshapes.names)
    try:
        prepared_h, _ = check_training_data(humans, blendshapes, "human labels only", config)
    except UserError as exc:
        return None, f"no fit on the human labels alone: {exc}"
    progress(_STEP_FRACTION["protocols"] - 0.01, "face fit on the human labels only (comparison)")
    with compute_backend(settings.compute()):
        face_h = _fit_face(prepared_h, blendshapes, config, cancelled, lambda *_: None)
    return label_comparison(face_h, prepared_h, face, prepare_for_lookup(table)), ""


def prepare_for_lookup(table: pd.DataFrame) -> pd.DataFrame:
    """The table's ``session, t_s`` and ``machine_*`` columns (the keys a fit's rows are looked up by)."""
    return table[[c for c in table.columns if c in ("session", "t_s") or c.startswith("machine_")]]


def _fit_face(prepared: pd.DataFrame, blendshapes: BlendshapeSet, config: FaceFitConfig,
              cancelled: Callable[[], bool], progress: ProgressFn) -> FaceModelFit:
    """The face grid search with a progress report (and a cancel check) after each fold."""
    n_folds = config.n_folds(prepared["participant"].nunique())
    done = [0]
    lo, hi = _STEP_FRACTION["hr"], _STEP_FRACTION["folds"]

    def fold(n: int) -> None:
        done[0] += n
        if cancelled():
            raise Cancelled("face CV")
        progress(lo + (hi - lo) * done[0] / max(n_folds, 1), f"face CV fold {done[0]} of {n_folds}")

    return fit_face_models(prepared, blendshapes.names, config, progress=fold)


# --------------------------------------------------------------------------- export and report


@dataclasses.dataclass
class ExportedModel:
    """What :func:`export_outcome` wrote: the model folder, its report and the metrics in model.json."""

    model_dir: Path
    report: Path
    metrics: dict[str, Any]
    #: what was not written, one phrase each (the refused float32 face.onnx, a failed report);
    #: empty when everything was written (:func:`partial_export_line`)
    not_written: list[str] = dataclasses.field(default_factory=list)


#: exit status of ``effortface train`` when the model folder was written but a later part was not
#: (the float32 engine file refused, the report failed): scripts tell it from 0 and from 2 (issue 26)
EXIT_MODEL_WRITTEN_PARTLY = 3


def partial_export_line(exported: ExportedModel) -> str:
    """One line saying what was saved and what was not (for stderr and the Train stage)."""
    return (f"model written to {exported.model_dir} (model.json, svr.npz, face_f64.onnx, MODEL_CARD.md"
            f"{'' if any(n.startswith('report') for n in exported.not_written) else ', report'}); not written: "
            + "; ".join(exported.not_written))


def export_outcome(outcome: TrainingOutcome, out: str | Path, *, force: bool = False,
                   progress: ProgressFn = _no_progress) -> ExportedModel:
    """Export the bundle (with ONNX, parity checks and model card) and write the report.

    Parameters
    ----------
    outcome : TrainingOutcome
        From :func:`train_models`.
    out : path-like
        The model folder to create.
    force : bool
        Replace an existing folder (see :func:`effortface.train.export.export_model`).
    progress : callable
        ``progress(fraction, text)`` before the export, before the report and at the end.

    Returns
    -------
    ExportedModel
        Its ``not_written`` names a refused float32 ``face.onnx`` and a report that failed; the
        model folder itself is written whenever this returns.
    """
    from effortface.train.export import (FACE_ONNX, build_bundle, engine_export_refusal,  # lazy: onnx
                                         export_model)
    from effortface.train.report import write_report

    o = outcome
    config = o.settings.config()
    progress(0.0, "export and parity checks")
    metrics = training_metrics(o.hr_eval, o.face, o.held_out, o.protocols)
    provenance = training_provenance(o.prepared, o.face, o.sources, o.settings.rater_policy, config)
    provenance["raters"] = o.settings.raters
    if o.label_origins:
        provenance["label_origins"] = o.label_origins
    if o.settings.raters == "humans+machine":
        from effortface.train.rater_sources import machine_agreement, machine_label_counts

        provenance["machine_labelled_seconds"] = machine_label_counts(o.prepared, o.blendshapes.names)
        metrics["machine_agreement"] = _finite_or_none(
            machine_agreement(o.sources, o.blendshapes, o.settings.rater_policy))
        metrics["face_label_comparison"] = (_finite_or_none(o.label_comparison.to_dict("records"))
                                            if o.label_comparison is not None else o.label_note)
    bundle = build_bundle(o.face, o.hr_eval.fit, o.blendshapes, metrics, provenance)
    model_dir = export_model(bundle, o.face, out, force=force, inputs=o.sources)
    refusal = engine_export_refusal(bundle.metrics)
    not_written = [] if refusal is None else [f"{FACE_ONNX} (float32 engine file refused: {refusal})"]
    progress(0.8, "report")
    report = model_dir / REPORT_DIR / "report.md"
    try:  # the model is written: a late failure of the figures must not lose it
        report = write_report(model_dir / REPORT_DIR, evaluation=o.hr_eval, series=o.series, fit=o.face,
                              held_out=o.held_out, protocols=o.protocols,
                              protocol_predictions=o.protocol_predictions,
                              header=report_header(bundle.provenance, model_dir),
                              label_comparison=(o.label_comparison if o.label_comparison is not None
                                                else o.label_note or None))
    except Exception as exc:  # noqa: BLE001 - any failure of the figures; the model stays
        not_written.append(f"report ({model_dir / REPORT_DIR}: {type(exc).__name__}: {exc})")
    except BaseException:  # a stop (SIGTERM, Ctrl-C): the model is whole, a half report is removed
        shutil.rmtree(model_dir / REPORT_DIR, ignore_errors=True)
        raise
    progress(1.0, "done")
    return ExportedModel(model_dir, report, bundle.metrics, not_written)


def run_training(table: pd.DataFrame, blendshapes: BlendshapeSet, out: str | Path, *,
                 settings: TrainSettings | None = None, force: bool = False,
                 sources: Sequence[str] = (), progress: bool = True) -> ExportedModel:
    """:func:`train_models` then :func:`export_outcome`, with progress bars on stderr.

    Parameters
    ----------
    table : DataFrame
        Long training table (:func:`training_table`).
    blendshapes : BlendshapeSet
        The blendshape set (the table's columns).
    out : path-like
        Model folder to write.
    settings : TrainSettings, optional
        The trainer's choices (default: :class:`TrainSettings` ()).
    force : bool
        Replace an existing model folder.
    sources : sequence of str
        Provenance for the model card.
    progress : bool
        Show the bars.

    Returns
    -------
    ExportedModel
    """
    settings = settings or TrainSettings()
    with ProgressBar("train", progress) as bar:
        outcome = train_models(table, blendshapes, settings, sources, bar)
    with ProgressBar("export", progress) as bar:
        return export_outcome(outcome, out, force=force, progress=bar)


def training_metrics(hr_eval: Any, face: Any, held: pd.DataFrame, protos: pd.DataFrame) -> dict[str, Any]:
    """JSON-ready metrics for model.json and the model card (undefined scores become null)."""
    return _finite_or_none({
        "hr": hr_eval.summary(),
        "hr_per_participant": {p: c.as_dict() for p, c in hr_eval.fit.per_participant.items()},
        "hr_tl_regression": hr_eval.fit.tl_regression.as_dict(),
        "face_held_out": held.to_dict("records"),
        "face_in_sample": training_scores(face).to_dict("records"),
        "face_protocols": protos.to_dict("records"),
        "face_cv": {b: {"best": s.best, "cv_mse": s.cv_mse, "cv_r": s.cv_r} for b, s in face.search.items()},
        "expressiveness": {p: {b: float(v) for b, v in row.items()}
                           for p, row in face.expressiveness.iterrows()},
    })


def _finite_or_none(value: Any) -> Any:
    """``value`` with NaN and infinities replaced by None: model.json is strict JSON, and a score
    can be undefined (e.g. the unseen-exercise protocol when the lab did one kind of exercise)."""
    if isinstance(value, dict):
        return {k: _finite_or_none(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite_or_none(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def label_origins(table: pd.DataFrame) -> dict[str, Any]:
    """The sessions table's note of key origins (:func:`effortface.train.dataset.sessions_table`):
    ``{"seconds": {origin: n}, "left_out": [...]}``, empty for a long table (no origins)."""
    if "label_origins" not in table.attrs:
        return {}
    return {"seconds": dict(table.attrs["label_origins"]), "left_out": list(table.attrs.get("left_out", []))}


def training_provenance(prepared: pd.DataFrame, face: Any, sources: Sequence[str], rater_policy: str,
                config: FaceFitConfig) -> dict[str, Any]:
    """Data and software description for model.json and the model card."""
    tls = prepared.groupby("participant", observed=True)["training_level"].first()
    return {
        "created_utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "software_version": _software_version(), "sources": list(sources),
        "participants": sorted(map(str, tls.index)), "n_participants": int(len(tls)),
        "training_levels": [float(v) for v in tls.to_numpy()],
        "n_sessions": int(prepared["session"].nunique()), "n_seconds": int(len(prepared)),
        "n_face_rows": int(len(face.data.x)), "face_fit": face.describe(), "rater_policy": rater_policy,
        "annotation_rule": ("n/a (trained from a long table)" if any(str(p).endswith(".csv") for p in sources)
                            else ANNOTATION_RULE), "cv": config.cv,
        "grid": config.grid, "max_rows_per_participant": config.max_rows_per_participant,
    }


def _software_version() -> str:
    """The effortface version (the one string in :mod:`effortface.core.version`)."""
    return __version__


def report_header(prov: dict[str, Any], model_dir: Path) -> dict[str, Any]:
    """The provenance lines shown at the top of the report."""
    keys = ("created_utc", "sources", "participants", "n_sessions", "n_seconds", "n_face_rows",
            "rater_policy", "raters", "cv")
    return {"model": str(model_dir), **{k: prov.get(k, "humans") for k in keys}}
