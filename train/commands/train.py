"""``effortface train (SESSION | DIR)... | --table CSV --out MODEL_DIR``: fit, evaluate, export, report.

Steps (progress bars on stderr): read the sessions or the table; add NHR and EPOC; fit and score
the paper's three heart-rate models (leave one participant out); search and fit the four face SVRs
(leave-one-participant-out CV by default); score them against the mean and linear baselines and the
paper's Fig. 3 protocols; export the bundle (``model.json``, ``svr.npz``, ``face.onnx``,
``MODEL_CARD.md``) with its parity checks; write ``MODEL_DIR/report/report.md`` with the plots.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import pandas as pd

from effortface.core.blendshapes import BlendshapeSet, load_blendshape_set
from effortface.core.errors import UserError
from effortface.train.dataset import blendshape_columns, read_table, sessions_table
from effortface.train.face_fit import (GRIDS, MIN_ROWS_PER_PARTICIPANT, FaceFitConfig, fit_face_models,
                            held_out_scores, protocol_scores)
from effortface.train.hr_fit import evaluate_hr_models



def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``effortface train``."""
    parser.add_argument("inputs", nargs="*", metavar="SESSION|DIR",
                        help="session folders, or folders of sessions")
    parser.add_argument("--table", metavar="CSV", help="long table instead of sessions (DESIGN.md)")
    parser.add_argument("--out", required=True, metavar="MODEL_DIR", help="model folder to write")
    parser.add_argument("--force", action="store_true", help="replace an existing MODEL_DIR")
    parser.add_argument("--rater-policy", default="mean", metavar="mean|RATER",
                        help="mean of raters (default) or one rater's key-frames")
    parser.add_argument("--cv", choices=("lopo", "kfold"), default="lopo",
                        help="leave-one-participant-out (default) or random-frame K-fold (inflated)")
    parser.add_argument("--grid", choices=tuple(GRIDS), default="small", help="hyper-parameter grid")
    parser.add_argument("--max-rows", type=int, default=FaceFitConfig().max_rows_per_participant,
                        metavar="N", help="face training rows per participant (1 Hz, evenly spaced)")
    parser.add_argument("--blendshapes", metavar="JSON", help="blendshape set file (default: the paper's)")


def check_inputs(args: argparse.Namespace) -> None:
    """UserError for contradictory or missing inputs, and for an --out that would lose data.

    See :func:`effortface.train.export.check_model_target`: an existing --out needs --force, and --force
    replaces only a model folder (or an empty one) that is not the current directory or an input.
    """
    from effortface.train.export import check_model_target  # lazy: onnx loads slowly

    if bool(args.inputs) == bool(args.table):
        raise UserError("inputs: expected session folders or --table CSV (one of the two), found "
                        + ("both" if args.inputs else "neither"))
    if args.max_rows < MIN_ROWS_PER_PARTICIPANT:
        raise UserError(f"--max-rows: expected at least {MIN_ROWS_PER_PARTICIPANT}, found {args.max_rows}")
    check_model_target(args.out, force=args.force, inputs=[*(args.inputs or [args.table]), args.blendshapes])


def load_table(args: argparse.Namespace, blendshapes: BlendshapeSet) -> tuple[pd.DataFrame, list[str]]:
    """The long table from ``--table`` or from the sessions, and its source names."""
    if args.table:
        return read_table(args.table, blendshapes), [str(args.table)]
    return sessions_table(args.inputs, blendshapes, args.rater_policy), [str(p) for p in args.inputs]


@dataclasses.dataclass
class TrainingResult:
    """What a training run produced (paths and the headline numbers)."""

    model_dir: Path
    report: Path
    metrics: dict[str, Any]


def run_training(table: pd.DataFrame, blendshapes: BlendshapeSet, out: str | Path, *,
                 config: FaceFitConfig | None = None, force: bool = False,
                 sources: Sequence[str] = (), rater_policy: str = "mean",
                 progress: bool = True) -> TrainingResult:
    """Fit, evaluate, export and report (the body of ``effortface train``).

    Parameters
    ----------
    table : DataFrame
        Long training table (from sessions or ``read_table``).
    blendshapes : BlendshapeSet
        The blendshape set (the table's columns).
    out : path-like
        Model folder to write.
    config : FaceFitConfig, optional
        Face-fit settings.
    force : bool
        Replace an existing model folder.
    sources, rater_policy
        Provenance for the model card.
    progress : bool
        Show tqdm bars on stderr.

    Returns
    -------
    TrainingResult
    """
    from tqdm import tqdm

    from effortface.train.pipeline import check_training_data, export_training

    config = config or FaceFitConfig()
    prepared, series = check_training_data(table, blendshapes, ", ".join(sources) or "table", config)
    steps = tqdm(total=5, desc="train", unit="step", file=sys.stderr, disable=not progress)

    def step(label: str) -> None:
        """Close the current step and name the next."""
        steps.set_postfix_str(label)
        steps.update()

    steps.set_postfix_str("heart-rate models")
    hr_eval = evaluate_hr_models(series)
    step("face SVR grid search")
    face = _fit_face(prepared, blendshapes, config, progress)
    step("evaluation")
    held = held_out_scores(face)
    protos, proto_preds = protocol_scores(face)
    step("export and parity checks")
    model_dir, report, bundle = export_training(
        prepared=prepared, series=series, hr_eval=hr_eval, face=face, held_out=held,
        protocols=protos, protocol_predictions=proto_preds, blendshapes=blendshapes,
        sources=sources, rater_policy=rater_policy, config=config, out=out, force=force,
        on_report=lambda: step("report"))
    step("done")
    steps.close()
    return TrainingResult(model_dir, report, bundle.metrics)


def _fit_face(prepared: pd.DataFrame, blendshapes: BlendshapeSet, config: FaceFitConfig,
              progress: bool) -> Any:
    """The face fit with a progress bar over its CV folds."""
    from tqdm import tqdm

    n = prepared["participant"].nunique()
    n_folds = min(n, config.max_folds) if config.cv == "lopo" else config.n_splits
    with tqdm(total=n_folds, desc="face CV folds", unit="fold", file=sys.stderr, leave=False,
              disable=not progress) as bar:
        return fit_face_models(prepared, blendshapes.names, config, progress=bar.update)


def run(args: argparse.Namespace) -> int:
    """Entry point of ``effortface train``."""
    check_inputs(args)
    blendshapes = load_blendshape_set(args.blendshapes)
    table, sources = load_table(args, blendshapes)
    missing = [c for c in blendshapes.names if c not in blendshape_columns(table, blendshapes)]
    if missing:
        raise UserError(f"blendshapes: expected columns {missing} in the training data, found none")
    config = FaceFitConfig(grid=dict(GRIDS[args.grid]), cv=args.cv, max_rows_per_participant=args.max_rows)
    if args.cv == "kfold":
        print("effortface train: warning: --cv kfold puts neighbouring, autocorrelated seconds of the "
              "same participant in training and test folds: its scores are inflated", file=sys.stderr)
    result = run_training(table, blendshapes, args.out, config=config, force=args.force,
                          sources=sources, rater_policy=args.rater_policy)
    hr = result.metrics["hr"]
    print(f"model: {result.model_dir}")
    print("heart rate (pooled and TL models on held-out participants): " + "; ".join(
        f"{k} r={v['r']:.2f} RMSE={v['rmse_pct']:.1f}%" for k, v in hr.items()))
    print(f"report: {result.report}")
    return 0
