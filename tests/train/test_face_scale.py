"""Face models at scale (issue 15): the exact/approximate switch at its documented size, the
approximation's accuracy against exact SVR, and training on a local Dask cluster (``--workers 2``)
giving the model of the serial run."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from effortface.cli import main
from effortface.core.blendshapes import DEFAULT_SET
from effortface.train.dataset import prepare, synthetic_table, write_table
from effortface.train.face_fit import (EXACT_MAX_ROWS, N_LANDMARKS, PENALTY_REFERENCE_ROWS, PREDICT_CHUNK_ROWS,
                                       FaceFitConfig, LandmarkRegressor, fit_face_models, fit_landmark_models,
                                       held_out_scores, kernel_products)
from effortface.synth.runtime import load_model

ROOT = Path(__file__).resolve().parents[2]
#: a local Dask cluster starts in a few seconds; a run that hangs fails instead of blocking CI
SUBPROCESS_TIMEOUT_S = 600


def _mean_held_out_rmse(fit) -> float:
    scores = held_out_scores(fit)
    return float(scores.loc[scores["model"] == "svr", "rmse_pct_unit"].mean())


def test_the_choice_switches_at_the_documented_size():
    config = FaceFitConfig()
    assert config.exact_max_rows == EXACT_MAX_ROWS == 3000
    assert config.method(EXACT_MAX_ROWS) == "exact_svr"
    assert config.method(EXACT_MAX_ROWS + 1) == "nystroem"
    assert config.max_total_rows is None  # no hidden total cap: every annotated second by default


def test_approximation_is_within_5_percent_of_exact_svr():
    """1,500 face rows (5 participants): both run; mean held-out RMSE over the blendshapes."""
    table = prepare(synthetic_table(n_participants=5, seconds=150, seed=11))
    exact = fit_face_models(table, DEFAULT_SET.names, FaceFitConfig(exact_max_rows=10**9))
    approx = fit_face_models(table, DEFAULT_SET.names, FaceFitConfig(exact_max_rows=100))
    assert exact.method == "exact_svr" and approx.method == "nystroem"
    assert len(approx.data.x) == len(exact.data.x) > 1000
    for model in approx.svrs.values():
        # at most N_LANDMARKS: the pick stops once the kernel is explained (no near-duplicates)
        assert isinstance(model, LandmarkRegressor) and 20 <= len(model.support_vectors_) <= N_LANDMARKS
    rmse_exact, rmse_approx = _mean_held_out_rmse(exact), _mean_held_out_rmse(approx)
    assert rmse_approx <= 1.05 * rmse_exact, (rmse_approx, rmse_exact)


def test_landmark_fit_is_kernel_ridge_on_the_landmarks():
    """With every row a landmark the approximation is exact kernel ridge regression."""
    rng = np.random.default_rng(0)
    xs = rng.normal(size=(60, 4))
    y = np.sin(xs[:, :1]) + 0.1 * rng.normal(size=(60, 1))
    landmarks, coefs = fit_landmark_models(xs, y, 0.5, [10.0], n_landmarks=60, seed=0)
    from sklearn.kernel_ridge import KernelRidge
    from sklearn.metrics.pairwise import rbf_kernel

    centred = y[:, 0] - coefs[10.0][-1, 0]
    assert len(landmarks) == 60
    # the penalty (n / PENALTY_REFERENCE_ROWS) / C: C keeps its meaning as the rows grow (issue 26)
    ref = KernelRidge(alpha=60 / PENALTY_REFERENCE_ROWS / 10.0, kernel="rbf", gamma=0.5).fit(xs, centred)
    pred = rbf_kernel(xs, landmarks, gamma=0.5) @ coefs[10.0][:-1, 0]
    np.testing.assert_allclose(pred, ref.predict(xs), atol=1e-4)


def _landmark_model(n_landmarks: int = N_LANDMARKS) -> LandmarkRegressor:
    rng = np.random.default_rng(1)
    xs = rng.normal(size=(3 * n_landmarks, 4))
    y = np.sin(xs[:, :1]) + 0.1 * rng.normal(size=(len(xs), 1))
    landmarks, coefs = fit_landmark_models(xs, y, 0.5, [10.0], n_landmarks=n_landmarks, seed=0)
    return LandmarkRegressor(landmarks, coefs[10.0][:-1, 0], coefs[10.0][-1, 0], 10.0, 0.5, 0.05)


def test_chunked_prediction_equals_the_whole_kernel_product():
    """Predictions over chunks of rows are the product with the whole kernel (to float noise), at
    chunk edges too; several weight matrices share each chunk's kernel."""
    from sklearn.metrics.pairwise import rbf_kernel

    model = _landmark_model()
    xs = np.random.default_rng(2).normal(size=(2 * PREDICT_CHUNK_ROWS + 17, 4))
    whole = rbf_kernel(xs, model.support_vectors_, gamma=0.5)
    np.testing.assert_allclose(model.predict(xs), whole @ model.dual_coef_[0] + model.intercept_[0],
                               rtol=0, atol=1e-12)
    w2 = np.random.default_rng(3).normal(size=(len(model.support_vectors_), 3))
    one, two = kernel_products(xs, model.support_vectors_, 0.5, [model.dual_coef_[0], w2])
    assert one.shape == (len(xs),) and two.shape == (len(xs), 3)
    np.testing.assert_allclose(two, whole @ w2, rtol=0, atol=1e-12)
    assert model.predict(xs[:0]).shape == (0,)


def test_prediction_memory_does_not_grow_with_the_rows():
    """issue 26: the approximation predicted every row at once, its (rows x landmarks) kernel and
    distance temporaries about 3 KB of peak memory per row (in-sample scores, protocols, folds).
    tracemalloc sees numpy's buffers: over 8x the rows the peak grows only by the output (8 bytes
    a row), not by the kernel."""
    import tracemalloc

    model = _landmark_model()
    rng = np.random.default_rng(4)
    peaks = []
    for n_rows in (2 * PREDICT_CHUNK_ROWS, 16 * PREDICT_CHUNK_ROWS):
        xs = rng.normal(size=(n_rows, 4))
        tracemalloc.start()
        model.predict(xs)
        peaks.append(tracemalloc.get_traced_memory()[1])
        tracemalloc.stop()
    grown_per_row = (peaks[1] - peaks[0]) / (14 * PREDICT_CHUNK_ROWS)
    assert grown_per_row < 64, (peaks, grown_per_row)  # a whole kernel: 300 landmarks x 8 bytes and more


@pytest.fixture(scope="module")
def big_table_csv(tmp_path_factory) -> Path:
    """3,200 face rows: above the switch, so the CLI picks the approximation by itself."""
    table = synthetic_table(n_participants=4, seconds=400, seed=3)
    return write_table(table, tmp_path_factory.mktemp("t") / "lab.csv")


def _train_subprocess(args: list[str]) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.run([sys.executable, "-m", "effortface", "train", *args], capture_output=True,
                          text=True, env=env, timeout=SUBPROCESS_TIMEOUT_S, cwd=ROOT)


def test_workers_2_gives_the_serial_model(big_table_csv, tmp_path):
    serial, dask = tmp_path / "serial", tmp_path / "dask"
    assert main(["train", "--table", str(big_table_csv), "--out", str(serial)]) == 0
    done = _train_subprocess(["--table", str(big_table_csv), "--out", str(dask), "--workers", "2"])
    assert done.returncode == 0, done.stderr[-2000:]
    with np.load(serial / "svr.npz") as a, np.load(dask / "svr.npz") as b:
        assert sorted(a.files) == sorted(b.files)
        for key in a.files:
            np.testing.assert_array_equal(a[key], b[key], err_msg=key)
    doc_a, doc_b = (json.loads((d / "model.json").read_text()) for d in (serial, dask))
    assert doc_a["svr"] == doc_b["svr"]
    assert doc_a["metrics"]["face_held_out"] == doc_b["metrics"]["face_held_out"]
    assert doc_a["metrics"]["face_protocols"] == doc_b["metrics"]["face_protocols"]
    # the choice, the landmarks and the rows are recorded
    fit_info = doc_a["provenance"]["face_fit"]
    assert fit_info["method"] == "nystroem" and fit_info["n_face_rows"] > EXACT_MAX_ROWS
    assert all(20 <= n <= N_LANDMARKS for n in fit_info["n_landmarks"]), fit_info
    assert f"on {fit_info['n_face_rows']} face rows" in (serial / "MODEL_CARD.md").read_text()
    # the runtime and face.onnx evaluate the approximation unchanged (export's parity checks ran)
    assert doc_a["metrics"]["export_parity"]["onnx_max_abs_diff"] < 1e-5
    assert load_model(serial).face.n_outputs == 4


def test_workers_and_scheduler_are_exclusive(big_table_csv, tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["train", "--table", str(big_table_csv), "--out", str(tmp_path / "m"), "--workers", "2",
              "--scheduler", "tcp://127.0.0.1:1"])
    assert exc.value.code == 2
    assert main(["train", "--table", str(big_table_csv), "--out", str(tmp_path / "m"),
                 "--workers", "0"]) == 2
    assert "--workers: expected a number of worker processes >= 1, found 0" in capsys.readouterr().err
