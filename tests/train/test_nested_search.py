"""The nested search and the shared fits behind the "as a game" scores and the protocols.

Each fast path is checked against the plain way it replaced, kept here as the reference: a grid
search on a copy of each outer fold's training rows, one model per blendshape fitted on its own.
"""

from __future__ import annotations

import itertools

import numpy as np
import pandas as pd
import pytest
from sklearn.preprocessing import StandardScaler

from effortface.train.dataset import hr_series, prepare, synthetic_table
from effortface.train.face_fit import (FaceData, FaceFitConfig, _pair_fold_mses, _search_fold, cv_folds,
                                       face_data, fit_face_models, fit_one, fit_predict, fold_numbers, grid_search,
                                       _predict_folds, _protocol_folds, nested_choices, protocol_scores,
                                       training_expressiveness)
from effortface.train.game_score import game_predictions

NAMES = ("mouth_stretch", "eye_squint", "brow_lower")
GRID = {"C": [0.3, 3.0, 30.0], "gamma": [0.1, 1.0], "epsilon": [0.05]}


@pytest.fixture(scope="module")
def lab() -> pd.DataFrame:
    """Five participants; one blendshape annotated on only part of the seconds (its own pattern)."""
    table = synthetic_table(n_participants=5, seconds=300, seed=4, blendshapes=NAMES)
    table.loc[table.index % 3 == 0, "brow_lower"] = np.nan
    return prepare(table)


def _subset(d: FaceData, rows: np.ndarray) -> FaceData:
    return FaceData(d.x[rows], d.y_norm[rows], d.e[rows], d.groups[rows], d.exercise[rows], d.t_s[rows],
                    d.session[rows], d.blendshapes)


@pytest.mark.parametrize("exact_max_rows", [100_000, 200], ids=["exact_svr", "nystroem"])
def test_nested_choices_are_a_search_on_each_outer_folds_training_rows(lab, exact_max_rows):
    config = FaceFitConfig(grid=GRID, exact_max_rows=exact_max_rows, n_landmarks=40)
    d = face_data(lab, NAMES)
    folds = cv_folds(d, "lopo", max_folds=config.max_folds)
    assert len(folds) == 5  # leave one participant out: the nested folds are exactly the plain ones
    plain = [{name: result.best for name, result in grid_search(_subset(d, train), config).items()}
             for train, _ in folds]
    assert nested_choices(d, config, folds) == plain
    assert len({str(c) for fold in plain for c in fold.values()}) > 1  # not one point chosen throughout


@pytest.mark.parametrize("exact_max_rows", [100_000, 200], ids=["exact_svr", "nystroem"])
def test_one_fit_scored_on_two_folds_gives_each_folds_own_errors(lab, exact_max_rows):
    """A pair's fit scored on both held-out folds equals two searches of the same training rows."""
    config = FaceFitConfig(grid=GRID, exact_max_rows=exact_max_rows, n_landmarks=40)
    d = face_data(lab, NAMES)
    folds = cv_folds(d, "lopo")
    fold_of = fold_numbers(folds, len(d.x))
    train = np.flatnonzero((fold_of != 1) & (fold_of != 3))
    method = config.method(len(train))
    paired = _pair_fold_mses(d, fold_of, 1, 3, config, method)
    for got, test in zip(paired, (folds[1][1], folds[3][1])):
        alone = _search_fold(d, train, test, config, method)[1]
        for point in itertools.product(GRID["C"], GRID["gamma"], GRID["epsilon"]):
            np.testing.assert_allclose(got[point], alone[point], rtol=1e-10, atol=0)


def test_fit_predict_equals_one_model_per_blendshape(lab):
    """Blendshapes sharing gamma and annotated rows share one landmark fit: the same predictions."""
    d = face_data(lab, NAMES)
    xs = StandardScaler().fit_transform(d.x)
    params = [{"C": 1.0, "gamma": 0.5, "epsilon": 0.05}, {"C": 10.0, "gamma": 0.5, "epsilon": 0.05},
              {"C": 1.0, "gamma": 0.5, "epsilon": 0.05}]
    tests = [xs[:50], xs[-70:] * 1.5]
    for method in ("exact_svr", "nystroem"):
        got = fit_predict(xs, d.y_norm, params, method, 60, 0, tests)
        for b, p in enumerate(params):
            ok = np.isfinite(d.y_norm[:, b])
            model = fit_one(xs[ok], d.y_norm[ok, b], p, method, 60, 0)
            for out, t in zip(got, tests):
                np.testing.assert_allclose(out[:, b], model.predict(t), rtol=1e-9, atol=1e-12)


def test_game_predictions_reuse_the_search_fits_exactly(lab):
    """With the approximation the nested models are the outer search's own fits of the fold: for a
    fully annotated blendshape the same as refitting on the fold's rows with the nested choice."""
    config = FaceFitConfig(grid=GRID, exact_max_rows=200, n_landmarks=40)
    fit = fit_face_models(lab, NAMES, config)
    assert fit.method == "nystroem"
    pred = game_predictions(fit, hr_series(lab), lab)
    d = fit.data
    folds = cv_folds(d, "lopo")
    for (train, test), inner in zip(folds, nested_choices(d, config, folds)):
        scaler = StandardScaler().fit(d.x[train])
        e_test = training_expressiveness(d, train, test)
        for b, name in enumerate(NAMES[:2]):  # annotated on every second
            model = fit_one(scaler.transform(d.x[train]), d.y_norm[train, b], inner[name], fit.method,
                            config.n_landmarks, config.seed)
            for got, x in ((pred.nested_measured, d.x[test]), (pred.as_game, pred.game_x[test])):
                expected = np.clip(model.predict(scaler.transform(x)) * e_test[:, b], 0, 1)
                np.testing.assert_allclose(got[test, b], expected, rtol=1e-9, atol=1e-12)
    assert np.isfinite(pred.as_game).all()  # the partly annotated blendshape too


def test_unseen_participant_protocol_uses_the_search_fits_as_a_refit_would(lab):
    """With the approximation the unseen-participant protocol reads the search's fits of each fold:
    the same as refitting each leave-one-participant-out fold with the chosen hyper-parameters
    (exactly so for the blendshapes annotated on every second, whose landmarks come from the same rows)."""
    config = FaceFitConfig(grid=GRID, exact_max_rows=200, n_landmarks=40)
    fit = fit_face_models(lab, NAMES, config)
    folds = _protocol_folds(fit.data, "unseen_participant", max_folds=config.max_folds)
    refitted = _predict_folds(fit, folds)
    read = protocol_scores(fit, ["unseen_participant"])[1]["unseen_participant"]
    np.testing.assert_allclose(read[:, :2], refitted[:, :2], rtol=1e-7, atol=1e-9)
    np.testing.assert_allclose(read[:, 2], refitted[:, 2], atol=0.05)  # other landmarks, the same model
    assert np.isfinite(read).all()
