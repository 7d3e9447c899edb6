"""Training benchmarks: ``python benchmarks/bench_training.py [--quick]``.

1. Full training on the sample lab (HR models, face grid search, export with parity checks,
   report): wall time (target under 2 minutes on 2 cores), and inside it the time of the fitting
   (``train_models``), of ``export_model`` (bundle files, ONNX graphs, parity checks, card) and of
   the report, each printed separately. One run.
2. Growth with participant-seconds on synthetic labs of increasing size: wall time of the fit, and
   the log-log slope (1 = linear, 2 = quadratic); the face rows are capped per participant and in
   all, and CV folds are capped, so the face part levels off once the caps bind.
3. The cached grid search against a plain ``GridSearchCV(StandardScaler + SVR)``, like for like:
   exact RBF SVRs on both sides (the cached search forced to its exact path), the same grid, the
   same folds (:func:`cv_folds`) and the same rows: time of each, the ratio, and both best CV MSEs
   per blendshape. Beside it, labelled as such and with no ratio, the approximate fit the trainer
   uses above ``EXACT_MAX_ROWS`` face rows (Nystroem landmarks: a different model, so a ratio to an
   exact search would not compare like with like). ``--cv-rows N`` caps the rows (evenly spaced
   per participant) for a short run. One run each.

Prints figures and ratios only (no assertion on time).
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from effortface.core.blendshapes import DEFAULT_SET  # noqa: E402
from effortface.train.dataset import prepare, sessions_table, synthetic_table  # noqa: E402
from effortface.train.face_fit import GRIDS, FaceFitConfig, face_data, grid_search, subsample  # noqa: E402

SAMPLE_LAB = ROOT / "sample_sessions"


def bench_full(table, label: str) -> dict[str, float]:
    """Wall time of a whole training run and of its parts: fitting, ``export_model``, the report."""
    import effortface.train.export as export
    import effortface.train.report as report
    from effortface.train.pipeline import TrainSettings, export_outcome, train_models

    parts = {"export_model": 0.0, "report": 0.0}

    def timed(name: str, fn):
        def wrapper(*args, **kwargs):
            t0 = time.perf_counter()
            try:
                return fn(*args, **kwargs)
            finally:
                parts[name] += time.perf_counter() - t0
        return wrapper

    originals = export.export_model, report.write_report
    export.export_model = timed("export_model", originals[0])
    report.write_report = timed("report", originals[1])
    try:
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            outcome = train_models(table, DEFAULT_SET, TrainSettings(), [label])
            t1 = time.perf_counter()
            export_outcome(outcome, Path(tmp) / "model")
            t2 = time.perf_counter()
    finally:
        export.export_model, report.write_report = originals
    return {"total": t2 - t0, "fit": t1 - t0, "export_outcome": t2 - t1, **parts}


def bench_growth(sizes: list[tuple[int, int]]) -> None:
    """Fit time against participant-seconds on synthetic labs."""
    from effortface.train.face_fit import fit_face_models, protocol_scores
    from effortface.train.hr_fit import evaluate_hr_models
    from effortface.train.dataset import hr_series

    print("\n2. growth with participant-seconds (synthetic labs, 2 sessions each, small grid)")
    print(f"{'participants':>12} {'seconds':>8} {'part-s':>8} {'prepare':>8} {'HR eval':>8} {'face+protocols':>15} {'total s':>8}")
    xs, ys = [], []
    for n, sec in sizes:
        table = synthetic_table(n_participants=n, seconds=sec, seed=n)
        t0 = time.perf_counter()
        prepared = prepare(table)
        t1 = time.perf_counter()
        evaluate_hr_models(hr_series(prepared))
        t2 = time.perf_counter()
        fit = fit_face_models(prepared, DEFAULT_SET.names, FaceFitConfig())
        protocol_scores(fit)
        t3 = time.perf_counter()
        xs.append(len(table))
        ys.append(t3 - t0)
        print(f"{n:>12} {sec:>8} {len(table):>8} {t1 - t0:>8.2f} {t2 - t1:>8.2f} {t3 - t2:>15.2f} {t3 - t0:>8.2f}")
    slope = np.polyfit(np.log(xs), np.log(ys), 1)[0]
    print(f"log-log slope of total time vs participant-seconds: {slope:.2f} (1 linear, 2 quadratic)")


def bench_cv(prepared, grid_name: str = "small", max_rows: int | None = None) -> None:
    """Cached per-fold kernels against plain GridSearchCV, both exact, same grid, folds and rows;
    then the approximate (Nystroem) search alone, labelled."""
    from sklearn.model_selection import GridSearchCV
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler
    from sklearn.svm import SVR

    from effortface.train.face_fit import cv_folds

    cfg = FaceFitConfig(grid=dict(GRIDS[grid_name]))
    prepared = prepared.dropna(subset=["w_per_kg", "p_per_kg", "nhr", "epoc_norm"])
    per = cfg.rows_per_participant(prepared["participant"].nunique())
    if max_rows is not None:
        per = min(per, max(1, max_rows // prepared["participant"].nunique()))
    data = face_data(subsample(prepared, per), DEFAULT_SET.names)
    n = len(data.x)
    exact = dataclasses.replace(cfg, exact_max_rows=max(n, cfg.exact_max_rows))
    folds = cv_folds(data, exact.cv, exact.n_splits, exact.seed, exact.max_folds)
    t0 = time.perf_counter()
    ours = grid_search(data, exact)
    t_ours = time.perf_counter() - t0
    grid = {f"svr__{k}": v for k, v in cfg.grid.items()}
    t0 = time.perf_counter()
    plain = {}
    for b, name in enumerate(data.blendshapes):
        ok = np.isfinite(data.y_norm[:, b])
        index = np.flatnonzero(ok)
        position = np.full(n, -1)
        position[index] = np.arange(len(index))
        cv = [(position[tr][ok[tr]], position[te][ok[te]]) for tr, te in folds]  # the same folds
        gs = GridSearchCV(make_pipeline(StandardScaler(), SVR(kernel="rbf")), grid, cv=cv,
                          scoring="neg_mean_squared_error", n_jobs=1)
        gs.fit(data.x[ok], data.y_norm[ok, b])
        plain[name] = (-gs.best_score_, {k.split("__")[1]: v for k, v in gs.best_params_.items()})
    t_plain = time.perf_counter() - t0
    print(f"\n3. grid search, exact RBF SVRs on both sides ({grid_name} grid, {n} rows, {len(folds)} "
          f"participant folds, the same folds on both sides; one run each)")
    print(f"cached kernels (exact): {t_ours:.2f} s; plain GridSearchCV (exact): {t_plain:.2f} s; "
          f"ratio plain / cached x{t_plain / t_ours:.2f}")
    print("  best CV MSE (mean over folds) per blendshape, cached exact vs plain exact:")
    for name in data.blendshapes:
        print(f"  {name:<14} cached {ours[name].cv_mse:.5f} {ours[name].best}  "
              f"plain {plain[name][0]:.5f} {plain[name][1]}")
    if n > cfg.exact_max_rows:
        t0 = time.perf_counter()
        approx = grid_search(data, cfg)
        t_approx = time.perf_counter() - t0
        print(f"  the approximate fit the trainer uses above {cfg.exact_max_rows} rows (Nystroem, "
              f"{cfg.n_landmarks} landmarks; a different model, no ratio): {t_approx:.2f} s")
        for name in data.blendshapes:
            print(f"  {name:<14} approximate {approx[name].cv_mse:.5f} {approx[name].best}")
    else:
        print(f"  ({n} rows <= {cfg.exact_max_rows}: the trainer's own fit is this exact search)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="smaller growth curve")
    parser.add_argument("--cv-rows", type=int, default=None,
                        help="cap the rows of the grid-search comparison (evenly spaced per participant)")
    parser.add_argument("--skip-growth", action="store_true", help="leave out the growth curve")
    args = parser.parse_args()
    if any(SAMPLE_LAB.glob("*/session.json")):
        table = sessions_table([SAMPLE_LAB])
        t = bench_full(table, str(SAMPLE_LAB))
        print(f"1. full training on the sample lab ({table['participant'].nunique()} participants, "
              f"{len(table)} participant-seconds; one run): {t['total']:.1f} s (target < 120 s)")
        print(f"   of which fitting {t['fit']:.1f} s, export and report {t['export_outcome']:.1f} s: "
              f"export_model {t['export_model']:.1f} s (bundle, ONNX graphs, parity checks, card), "
              f"report {t['report']:.1f} s")
        bench_cv(prepare(table), max_rows=args.cv_rows)
    else:
        print("1. sample lab not generated: skipped (python sample_sessions/generate.py)")
    sizes = [(3, 600), (6, 600), (6, 1200), (12, 1200)] if args.quick else \
        [(3, 600), (6, 600), (6, 1200), (12, 1200), (12, 2400), (24, 2400)]
    if not args.skip_growth:
        bench_growth(sizes)


if __name__ == "__main__":
    main()
