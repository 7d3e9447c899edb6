"""The end of a training run, shared by ``effortface train`` and the Train stage: metrics and
provenance for ``model.json``, the bundle export (train/export.py) and the report (train/report.py).
"""

from __future__ import annotations

import datetime as _dt
import math
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import pandas as pd

from effortface.core.blendshapes import BlendshapeSet
from effortface.train.dataset import hr_series, prepare
from effortface.train.face_fit import FaceFitConfig, check_face_table
from effortface.train.hr_fit import check_hr_series
from effortface.core.version import __version__

REPORT_DIR = "report"


def export_training(*, prepared: pd.DataFrame, series: Any, hr_eval: Any, face: Any,
                    held_out: pd.DataFrame, protocols: pd.DataFrame, protocol_predictions: Any,
                    blendshapes: BlendshapeSet, sources: Sequence[str], rater_policy: str,
                    config: FaceFitConfig, out: str | Path, force: bool = False,
                    on_report: Callable[[], None] | None = None) -> tuple[Path, Path, Any]:
    """Export the bundle (with ONNX, parity checks and model card) and write the report.

    Parameters
    ----------
    prepared, series, hr_eval, face, held_out, protocols, protocol_predictions
        The outputs of the training steps (train/dataset.py, train/hr_fit.py, train/face_fit.py).
    blendshapes : BlendshapeSet
    sources : sequence of str
        Sessions or table the data came from (provenance).
    rater_policy : str
    config : FaceFitConfig
    out : path
        The model folder to create.
    force : bool
        Replace an existing folder.
    on_report : callable, optional
        Called between the export and the report (progress).

    Returns
    -------
    model_dir, report_path, bundle
    """
    from effortface.train.export import build_bundle, export_model
    from effortface.train.report import write_report

    metrics = training_metrics(hr_eval, face, held_out, protocols)
    provenance = training_provenance(prepared, face, sources, rater_policy, config)
    bundle = build_bundle(face, hr_eval.fit, blendshapes, metrics, provenance)
    model_dir = export_model(bundle, face, out, force=force, inputs=sources)
    if on_report is not None:
        on_report()
    report = write_report(model_dir / REPORT_DIR, evaluation=hr_eval, series=series, fit=face,
                          held_out=held_out, protocols=protocols,
                          protocol_predictions=protocol_predictions,
                          header=report_header(bundle.provenance, model_dir))
    return model_dir, report, bundle


def training_metrics(hr_eval: Any, face: Any, held: pd.DataFrame, protos: pd.DataFrame) -> dict[str, Any]:
    """JSON-ready metrics for model.json and the model card (undefined scores become null)."""
    return _finite_or_none({
        "hr": hr_eval.summary(),
        "hr_per_participant": {p: c.as_dict() for p, c in hr_eval.fit.per_participant.items()},
        "hr_tl_regression": hr_eval.fit.tl_regression.as_dict(),
        "face_held_out": held.to_dict("records"),
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


def training_provenance(prepared: pd.DataFrame, face: Any, sources: Sequence[str], rater_policy: str,
                config: FaceFitConfig) -> dict[str, Any]:
    """Data and software description for model.json and the model card."""
    tls = prepared.groupby("participant")["training_level"].first()
    return {
        "created_utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "software_version": _software_version(), "sources": list(sources),
        "participants": sorted(map(str, tls.index)), "n_participants": int(len(tls)),
        "training_levels": [float(v) for v in tls.to_numpy()],
        "n_sessions": int(prepared["session"].nunique()), "n_seconds": int(len(prepared)),
        "n_face_rows": int(len(face.data.x)), "rater_policy": rater_policy, "cv": config.cv,
        "grid": config.grid, "max_rows_per_participant": config.max_rows_per_participant,
    }


def _software_version() -> str:
    """The effortface version (the one string in :mod:`effortface.core.version`)."""
    return __version__


def report_header(prov: dict[str, Any], model_dir: Path) -> dict[str, Any]:
    """The provenance lines shown at the top of the report."""
    keys = ("created_utc", "sources", "participants", "n_sessions", "n_seconds", "n_face_rows",
            "rater_policy", "cv")
    return {"model": str(model_dir), **{k: prov[k] for k in keys}}


def check_training_data(table: pd.DataFrame, blendshapes: BlendshapeSet, source: str,
                        config: FaceFitConfig) -> tuple[pd.DataFrame, list[Any]]:
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
