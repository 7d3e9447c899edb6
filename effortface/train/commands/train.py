"""``effortface train (SESSION | DIR)... | --table CSV --out MODEL_DIR``: fit, evaluate, export, report.

Steps (progress bars on stderr): read the sessions or the table; add NHR and EPOC; fit and score
the paper's three heart-rate models (leave one participant out); search and fit the four face SVRs
(leave-one-participant-out CV by default); score them against the mean and linear baselines and the
paper's Fig. 3 protocols; export the bundle (``model.json``, ``svr.npz``, ``face.onnx``,
``MODEL_CARD.md``) with its parity checks; write ``MODEL_DIR/report/report.md`` with the plots.

Exit status: 0 everything written; 2 bad input or a failed fit (no model folder); 3 the model
folder was written (model.json, svr.npz, face_f64.onnx, MODEL_CARD.md) but the float32 engine file
``face.onnx`` was refused (over its 1e-4 bound; the measured error is in model.json and the card)
or the report failed: one stderr line says what was saved and what was not.
"""

from __future__ import annotations

import argparse
import sys

from effortface.core.docs import DESIGN, SCIENCE
from effortface.core.blendshapes import load_blendshape_set
from effortface.core.errors import UserError
from effortface.train.dataset import RATER_SOURCES
from effortface.train.face_fit import EXACT_MAX_ROWS, GRIDS, MIN_ROWS_PER_PARTICIPANT, FaceFitConfig
from effortface.synth.parallel import add_compute_arguments
from effortface.train.pipeline import (EXIT_MODEL_WRITTEN_PARTLY, TrainSettings, partial_export_line,
                                       run_training, training_table)


#: the shipped documents ``--help`` cites (effortface.core.docs)
HELP_DOCS = (DESIGN, SCIENCE)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``effortface train``."""
    parser.add_argument("inputs", nargs="*", metavar="SESSION|DIR",
                        help="session folders, or folders of sessions")
    parser.add_argument("--table", metavar="CSV", help=f"long table instead of sessions (format: {DESIGN})")
    parser.add_argument("--out", required=True, metavar="MODEL_DIR",
                        help="model folder to write (exit status 3: written, but the float32 face.onnx "
                             "was refused or the report failed; see docs/DESIGN.md)")
    parser.add_argument("--force", action="store_true", help="replace an existing MODEL_DIR")
    parser.add_argument("--rater-policy", default="mean", metavar="mean|RATER",
                        help="mean of raters (default) or one rater's key-frames; complete tracks only "
                             "(keys over the whole video, no gap over 30 s, pass finished)")
    parser.add_argument("--raters", choices=RATER_SOURCES, default="humans",
                        help="who labels the face: the humans' key-frames (default), or also the machine "
                             "rater (machine/face_landmarker.csv from effortface preannotate) where no human "
                             "keyed; then the report compares held-out scores on human labels of a fit on "
                             "human labels only and of this one")
    parser.add_argument("--cv", choices=("lopo", "kfold"), default="lopo",
                        help="leave-one-participant-out (default) or random-frame K-fold (inflated)")
    parser.add_argument("--grid", choices=tuple(GRIDS), default="small", help="hyper-parameter grid")
    parser.add_argument("--C", dest="c_values", type=float, nargs="+", metavar="C",
                        help="values of the face models' C to search, in place of the grid's "
                             f"(small: {' '.join(f'{v:g}' for v in GRIDS['small']['C'])}); C weighs each "
                             "training row's error against the smoothness penalty")
    parser.add_argument("--gamma", dest="gamma_values", type=float, nargs="+", metavar="GAMMA",
                        help="values of the RBF gamma (standardised features) to search, in place of the "
                             f"grid's (small: {' '.join(f'{v:g}' for v in GRIDS['small']['gamma'])})")
    parser.add_argument("--max-rows", type=int, default=FaceFitConfig().max_rows_per_participant,
                        metavar="N", help="face training rows per participant (1 Hz, evenly spaced; "
                        f"default {FaceFitConfig().max_rows_per_participant}); above "
                        f"{EXACT_MAX_ROWS} rows in all the SVRs become a Nystroem approximation")
    add_compute_arguments(parser, "the cross-validation folds")
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


def _values(values: list[float] | None) -> tuple[float, ...] | None:
    """An option's list of numbers as a tuple (None when not given)."""
    return None if values is None else tuple(values)


def run(args: argparse.Namespace) -> int:
    """Entry point of ``effortface train``."""
    check_inputs(args)
    settings = TrainSettings(rater_policy=args.rater_policy, raters=args.raters, grid=args.grid, cv=args.cv,
                             max_rows_per_participant=args.max_rows, workers=args.workers,
                             scheduler=args.scheduler, c_values=_values(args.c_values),
                             gamma_values=_values(args.gamma_values))
    blendshapes = load_blendshape_set(args.blendshapes)
    table, sources = training_table(args.inputs, args.table, blendshapes, args.rater_policy, args.raters)
    if args.cv == "kfold":
        print("effortface train: warning: --cv kfold puts neighbouring, autocorrelated seconds of the "
              "same participant in training and test folds: its scores are inflated", file=sys.stderr)
    result = run_training(table, blendshapes, args.out, settings=settings, force=args.force,
                          sources=sources)
    hr = result.metrics["hr"]
    print(f"model: {result.model_dir}")
    print("heart rate (held out unless marked in-sample): " + "; ".join(
        f"{k} r={v['r']:.2f} RMSE={v['rmse_pct']:.1f}%" for k, v in hr.items()))
    if result.not_written:
        print(f"effortface train: {partial_export_line(result)}", file=sys.stderr)
        return EXIT_MODEL_WRITTEN_PARTLY
    print(f"report: {result.report}")
    return 0
