"""Training benchmarks: ``python benchmarks/bench_training.py [--quick]``.

1. Full training on the sample lab (``run_training``: HR models, face grid search, export with
   parity checks, report): wall time (target under 2 minutes on 2 cores).
2. Growth with participant-seconds on synthetic labs of increasing size: wall time of the fit, and
   the log-log slope (1 = linear, 2 = quadratic); the face rows are capped per participant and in
   all, and CV folds are capped, so the face part levels off once the caps bind.
3. The cached grid search against a plain ``GridSearchCV(StandardScaler + SVR)`` over the same grid
   and the same leave-one-participant-out folds: time, speed-up ratio and the best CV MSE of each.

Prints figures and ratios only (no assertion on time).
"""

from __future__ import annotations

import argparse
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


def bench_full(table, label: str) -> float:
    """Wall time of a whole training run (export and report included)."""
    from effortface.train.pipeline import run_training

    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        run_training(table, DEFAULT_SET, Path(tmp) / "model", progress=False, sources=[label])
        return time.perf_counter() - t0


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


def bench_cv(prepared, grid_name: str = "small") -> None:
    """Cached per-fold kernels against plain GridSearchCV, same grid and folds."""
    from sklearn.model_selection import GridSearchCV, LeaveOneGroupOut
    from sklearn.pipeline import make_pipeline
    from sklearn.preprocessing import StandardScaler
    from sklearn.svm import SVR

    cfg = FaceFitConfig(grid=dict(GRIDS[grid_name]))
    prepared = prepared.dropna(subset=["w_per_kg", "p_per_kg", "nhr", "epoc_norm"])
    data = face_data(subsample(prepared, cfg.rows_per_participant(prepared["participant"].nunique())),
                     DEFAULT_SET.names)
    t0 = time.perf_counter()
    ours = grid_search(data, cfg)
    t_ours = time.perf_counter() - t0
    grid = {f"svr__{k}": v for k, v in cfg.grid.items()}
    t0 = time.perf_counter()
    plain = {}
    for b, name in enumerate(data.blendshapes):
        ok = np.isfinite(data.y_norm[:, b])
        gs = GridSearchCV(make_pipeline(StandardScaler(), SVR(kernel="rbf")), grid, cv=LeaveOneGroupOut(),
                          scoring="neg_mean_squared_error", n_jobs=1)
        gs.fit(data.x[ok], data.y_norm[ok, b], groups=data.groups[ok])
        plain[name] = (-gs.best_score_, {k.split("__")[1]: v for k, v in gs.best_params_.items()})
    t_plain = time.perf_counter() - t0
    print(f"\n3. grid search ({grid_name} grid, {len(data.x)} rows, leave-one-participant-out)")
    print(f"cached kernels: {t_ours:.2f} s; plain GridSearchCV: {t_plain:.2f} s; "
          f"speed-up x{t_plain / t_ours:.2f}")
    for name in data.blendshapes:
        print(f"  {name:<14} best CV MSE ours {ours[name].cv_mse:.5f} {ours[name].best}  "
              f"plain {plain[name][0]:.5f} {plain[name][1]}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="smaller growth curve")
    args = parser.parse_args()
    if any(SAMPLE_LAB.glob("*/session.json")):
        table = sessions_table([SAMPLE_LAB])
        secs = bench_full(table, str(SAMPLE_LAB))
        print(f"1. full training on the sample lab ({table['participant'].nunique()} participants, "
              f"{len(table)} participant-seconds): {secs:.1f} s (target < 120 s)")
        bench_cv(prepare(table))
    else:
        print("1. sample lab not generated: skipped (python sample_sessions/generate.py)")
    sizes = [(3, 600), (6, 600), (6, 1200), (12, 1200)] if args.quick else \
        [(3, 600), (6, 600), (6, 1200), (12, 1200), (12, 2400), (24, 2400)]
    bench_growth(sizes)


if __name__ == "__main__":
    main()
