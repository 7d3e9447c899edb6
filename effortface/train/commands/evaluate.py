"""``effortface evaluate MODEL_DIR (SESSION | DIR)... | --table CSV``: re-score a bundle on other data.

The scores are :func:`effortface.train.evaluation.evaluate_bundle`'s (the bundle loaded through the
runtime, as a game would load it); this module parses the options and prints the report, which
says how the predictions were scaled (``--known-expressiveness`` borrows the scored participants'
own key-frames; off by default).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from effortface.core.docs import DESIGN, SCIENCE
from effortface.core.errors import UserError
from effortface.train.evaluation import evaluate_bundle, evaluation_report
from effortface.train.pipeline import training_table


#: the shipped documents ``--help`` cites (effortface.core.docs)
HELP_DOCS = (DESIGN, SCIENCE)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``effortface evaluate``."""
    parser.add_argument("model", metavar="MODEL_DIR", help="a model folder written by 'effortface train'")
    parser.add_argument("inputs", nargs="*", metavar="SESSION|DIR", help="sessions, or folders of sessions")
    parser.add_argument("--table", metavar="CSV", help="long table instead of sessions")
    parser.add_argument("--rater-policy", default="mean", metavar="mean|RATER",
                        help="mean of raters (default) or one rater's key-frames; complete tracks only "
                             "(keys over the whole video, no gap over 30 s, pass finished)")
    parser.add_argument("--known-expressiveness", action="store_true",
                        help="multiply predictions by each scored participant's own maximal key-framed "
                             "weight (borrows from the labels it is scored against); default: the mean "
                             "expressiveness of the model's training participants")


def check_model_dir(model: str) -> Path:
    """The MODEL_DIR argument as a Path, or UserError (one line) if it is not a model folder.

    ``default`` (the built-in rule model other commands accept) is refused by name: it has no
    fitted heart-rate or face models to score.

    Raises
    ------
    UserError
        For ``default``, a missing path, or a file.
    """
    expected = f"{model}: expected a model folder written by 'effortface train' (model.json, svr.npz)"
    if model in ("default", "paper-2015"):  # runtime.BUILT_IN_MODELS
        raise UserError(f"{expected}, found {model!r} (a built-in rule model has no fitted models "
                        "to evaluate)")
    path = Path(model)
    if not path.is_dir():
        raise UserError(f"{expected}, found {'a file' if path.exists() else 'no such folder'}")
    return path


def run(args: argparse.Namespace) -> int:
    """Entry point of ``effortface evaluate``."""
    from effortface.synth.bundle import read_bundle

    if bool(args.inputs) == bool(args.table):
        raise UserError("inputs: expected session folders or --table CSV (one of the two), found "
                        + ("both" if args.inputs else "neither"))
    check_model_dir(args.model)
    shapes = read_bundle(args.model).blendshapes
    table, sources = training_table(args.inputs, args.table, shapes, args.rater_policy)
    source = ", ".join(sources)
    ev = evaluate_bundle(args.model, table, source, known_expressiveness=args.known_expressiveness)
    print(evaluation_report(ev, args.model, source))
    return 0
