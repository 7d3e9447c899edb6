"""Held-out face scores as a game uses the model: no heart rate and no key-frame of the scored participant."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from effortface.train.dataset import hr_series, prepare, synthetic_table
from effortface.train.face_fit import FaceFitConfig, fit_face_models
from effortface.train.game_score import GamePredictions, game_predictions, game_scores, simulated_features
from effortface.synth.physiology import PAPER_REGRESSION

NAMES = ("mouth_stretch", "eye_squint")
SCORED = "P01"


def _predictions(table: pd.DataFrame) -> tuple[GamePredictions, np.ndarray, np.ndarray]:
    """Game predictions of a synthetic lab, and the scored participant's face rows (groups, t_s)."""
    prepared = prepare(table)
    fit = fit_face_models(prepared, NAMES, FaceFitConfig(grid={"C": [1.0, 10.0], "gamma": [0.5],
                                                               "epsilon": [0.05]}))
    pred = game_predictions(fit, hr_series(prepared), prepared)
    rows = fit.data.groups == SCORED
    return pred, rows, fit.data.t_s[rows]


@pytest.fixture(scope="module")
def lab() -> pd.DataFrame:
    return synthetic_table(n_participants=4, seconds=240, seed=3, blendshapes=NAMES)


@pytest.fixture(scope="module")
def original(lab: pd.DataFrame) -> tuple[GamePredictions, np.ndarray, np.ndarray]:
    return _predictions(lab)


def _scrambled(lab: pd.DataFrame) -> pd.DataFrame:
    """The scored participant's heart rate permuted in time and their key-frames replaced by noise."""
    out = lab.copy()
    rng = np.random.default_rng(0)
    mine = out["participant"] == SCORED
    hr = out.loc[mine, "hr_bpm"].to_numpy(float, copy=True)
    finite = np.isfinite(hr)
    hr[finite] = rng.permutation(hr[finite])
    out.loc[mine, "hr_bpm"] = hr
    for name in NAMES:
        col = out.loc[mine, name].to_numpy(float, copy=True)
        keyed = np.isfinite(col)
        col[keyed] = rng.uniform(0.0, 1.0, keyed.sum())
        out.loc[mine, name] = col
    return out


def test_scored_participants_heart_rate_and_key_frames_cannot_reach_their_prediction(
        lab: pd.DataFrame, original: tuple[GamePredictions, np.ndarray, np.ndarray]) -> None:
    before, rows, t_before = original
    after, rows_after, t_after = _predictions(_scrambled(lab))
    np.testing.assert_array_equal(t_before, t_after)  # the same seconds are scored
    np.testing.assert_array_equal(before.as_game[rows], after.as_game[rows_after])
    assert np.isfinite(before.as_game[rows]).all()
    # the measured-NHR row does see the heart rate: the scramble is strong enough to show a leak
    assert not np.allclose(before.nested_measured[rows], after.nested_measured[rows_after])


def test_game_features_are_simulated_not_measured(original: tuple[GamePredictions, np.ndarray, np.ndarray],
                                                  lab: pd.DataFrame) -> None:
    """The game row's NHR feature of the scored participant is not their measured NHR."""
    pred, rows, _ = original
    prepared = prepare(lab)
    measured = prepared.dropna(subset=["nhr"])
    assert pred.game_x[rows, 2].max() <= 1.0
    assert not np.allclose(np.sort(pred.game_x[rows, 2]),
                           np.sort(measured.loc[measured["participant"] == SCORED, "nhr"].to_numpy())[:rows.sum()])


def test_simulated_features_start_at_rest_and_rise_with_work(lab: pd.DataFrame) -> None:
    prepared = prepare(lab)
    s = hr_series(prepared)[0]
    person = prepared.iloc[0]
    still = type(s)(s.participant, s.session, s.training_level, s.t_s, np.zeros_like(s.w_per_kg), s.nhr,
                    s.hr_rest_bpm, s.hr_max_bpm)
    nhr0, epoc0 = simulated_features(still, person, PAPER_REGRESSION)
    nhr, epoc = simulated_features(s, person, PAPER_REGRESSION)
    assert nhr0.max() == pytest.approx(0.0, abs=1e-12) and epoc0.max() == pytest.approx(0.0, abs=1e-9)
    assert nhr.max() > 0.1 and epoc.max() > 0.0


def test_game_scores_have_both_rows_per_blendshape(lab: pd.DataFrame) -> None:
    prepared = prepare(lab)
    fit = fit_face_models(prepared, NAMES, FaceFitConfig(grid={"C": [1.0], "gamma": [0.5], "epsilon": [0.05]}))
    scores, _ = game_scores(fit, hr_series(prepared), prepared)
    assert sorted(scores["model"].unique()) == ["svr_as_game", "svr_nested_measured_nhr"]
    assert len(scores) == 2 * len(NAMES) and scores["r"].notna().all()
