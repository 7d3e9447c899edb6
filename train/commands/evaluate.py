"""``effortface evaluate MODEL_DIR (SESSION | DIR)... | --table CSV``: re-score a bundle on other data.

The bundle is loaded through the runtime (:func:`effortface.train.runtime.load_model`), as a game would load it:

- heart rate: the bundle's training-level regression at each participant's TL, simulated over each
  whole session from its first measured value (r, RMSE in % of the NHR range, HR RMSE in bpm);
- face: the SVRs on the measured [w, p, NHR, EPOC_norm] of each second, times the participant's own
  expressiveness (maximal key-framed weight), clipped, against the key-framed weights (r, RMSE in %
  of the observed range and of [0, 1]).
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np
import pandas as pd

from effortface.core.errors import UserError
from effortface.train.dataset import hr_series, prepare, read_table, sessions_table
from effortface.train.face_fit import expressiveness, weight_metrics
from effortface.train.hr_fit import HrCoefficients, score_series, simulate_series


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``effortface evaluate``."""
    parser.add_argument("model", metavar="MODEL_DIR", help="a model folder written by 'effortface train'")
    parser.add_argument("inputs", nargs="*", metavar="SESSION|DIR", help="sessions, or folders of sessions")
    parser.add_argument("--table", metavar="CSV", help="long table instead of sessions")
    parser.add_argument("--rater-policy", default="mean", metavar="mean|RATER",
                        help="mean of raters (default) or one rater's key-frames")


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
    """
    from effortface.train.bundle import read_bundle
    from effortface.train.runtime import load_model

    model = load_model(model_dir)
    bundle = read_bundle(model_dir)
    names = list(model.blendshapes.names)
    missing = [n for n in names if n not in table.columns]
    if missing:
        raise UserError(f"{source}: expected the model's blendshape columns {', '.join(missing)}, "
                        f"found {', '.join(table.columns)}")
    from effortface.train.physiology import EpocParams, NhrParams
    prepared = prepare(table, bundle.physiology["hr_max_formula"], EpocParams(**bundle.physiology["epoc"]),
                       source)
    reg = bundle.nhr_regression
    hr_rows = []
    for s in hr_series(prepared):
        tl = s.training_level
        coef = HrCoefficients.from_nhr_params(NhrParams.from_training_level(tl, reg))
        hr_rows.append(dataclasses.asdict(score_series(s, simulate_series(s, coef), "tl_regression")))
    e = expressiveness(prepared, names).loc[prepared["participant"]].to_numpy(float)
    x = prepared[["w_per_kg", "p_per_kg", "nhr", "epoc_norm"]].to_numpy(float)
    ok = np.isfinite(x).all(axis=1)
    pred = np.full((len(x), len(names)), np.nan)
    pred[ok] = np.clip(model.face.predict(x[ok]) * e[ok], 0, 1)
    face_rows = [{"blendshape": n, **weight_metrics(prepared[n].to_numpy(float), pred[:, b])}
                 for b, n in enumerate(names)]
    return Evaluation(pd.DataFrame(hr_rows), pd.DataFrame(face_rows))


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
    from effortface.train.bundle import read_bundle
    from effortface.train.report import _md

    if bool(args.inputs) == bool(args.table):
        raise UserError("inputs: expected session folders or --table CSV (one of the two), found "
                        + ("both" if args.inputs else "neither"))
    check_model_dir(args.model)
    shapes = read_bundle(args.model).blendshapes
    if args.table:
        table, source = read_table(args.table, shapes), str(args.table)
    else:
        table, source = sessions_table(args.inputs, shapes, args.rater_policy), ", ".join(args.inputs)
    ev = evaluate_bundle(args.model, table, source)
    print(f"# evaluation of {args.model} on {source}\n")
    print("## heart rate (TL regression, simulated over whole sessions)\n")
    print(_md(ev.hr[["participant", "session", "r", "rmse_pct", "hr_rmse_bpm", "n"]]))
    print(f"\nmean: r {ev.hr['r'].mean():.3f}, RMSE {ev.hr['rmse_pct'].mean():.1f} % of the NHR range, "
          f"{ev.hr['hr_rmse_bpm'].mean():.1f} bpm\n")
    print("## face (SVR x each participant's expressiveness)\n")
    print(_md(ev.face))
    return 0
