"""Held-out face scores as a game uses the model (SCIENCE_NOTES "Face scores as a game uses the model").

A game has the character's motion (work and power) and its demographics, never a measured heart
rate and never the actor's key-frames. :func:`game_scores` scores each participant in turn with
everything fitted without them (leave one participant out; participant-grouped folds for large labs):

1. **Heart rate.** The paper's heart-rate models fitted on the other participants
   (:func:`~effortface.train.hr_fit.fit_hr_model`); their training-level regression at the scored
   participant's training level gives the NHR coefficients.
2. **NHR and EPOC from work.** The runtime's physiology
   (:func:`~effortface.synth.physiology.simulate`) runs over each of the participant's sessions on
   a 1 s grid, from rest (NHR 0, EPOC 0), on the session's work only; its NHR and EPOC_norm replace
   the measured ones in the face features.
3. **Hyper-parameters (nested).** The face grid search runs on the other participants only
   (:func:`~effortface.train.face_fit.nested_choices`: its inner folds are the other outer folds,
   so with leave one participant out, its own leave-one-participant-out folds), and the fold's
   models are fitted on them with its choice. With the Nystroem approximation and the default
   participant folds these models are the outer search's own fits of that fold at the chosen
   point (the same rows, scaler, landmarks and penalty; kept by
   :func:`~effortface.train.face_fit.grid_search`), so they are not fitted twice.
4. **Expressiveness.** The mean maximal key-framed weight of the other participants (what
   :func:`~effortface.train.face_fit.training_expressiveness` gives an unseen participant).

So the scored participant's heart rate and key-frames cannot reach their predictions (a test
scrambles them). Two rows come out per blendshape: ``svr_as_game`` (the above) and
``svr_nested_measured_nhr`` (the same nested fits on the measured NHR and EPOC), which, beside the
search's own ``svr`` row (hyper-parameters chosen on the scored folds), separates the two
optimisms: hyper-parameters and measured heart rate.
"""

from __future__ import annotations

import dataclasses
import types
from collections.abc import Sequence

import numpy as np
import pandas as pd
from sklearn.preprocessing import StandardScaler

from effortface.train.face_fit import (METHODS, FaceModelFit, cv_folds, fit_predict, nested_choices,
                                       search_fit_predictions, training_expressiveness, weight_metrics)
from effortface.train.hr_fit import HrSeries, fit_hr_model
from effortface.synth.physiology import EpocParams, PhysiologyParams, simulate

#: Model labels of :func:`game_scores`.
GAME_MODELS = ("svr_as_game", "svr_nested_measured_nhr")
#: What each held-out face model row means, in the words the report and the model card use.
MODEL_MEANINGS = {
    "svr_as_game": "as a game uses it: NHR and EPOC simulated from work by the heart model fitted "
                   "without the participant, no measured heart rate, no key-frame of the participant "
                   "(hyper-parameters chosen on the other participants only)",
    "svr_nested_measured_nhr": "measured NHR and EPOC, hyper-parameters chosen on the other "
                               "participants only",
    "svr": "measured NHR and EPOC, hyper-parameters chosen by the same folds that score it",
    "mean": "baseline: the training mean",
    "linear": "baseline: linear regression on the measured features",
    "svr_known_expressiveness": "svr times the participant's own maximal key-framed weight "
                                "(borrows from the test labels)",
}


def headline(held_out: pd.DataFrame) -> tuple[str, float, float]:
    """The face score a report leads with: the model label and its mean r and RMSE % of range.

    ``svr_as_game`` when the table has it (runs from this version on), else ``svr``.
    """
    model = "svr_as_game" if (held_out["model"] == "svr_as_game").any() else "svr"
    rows = held_out[held_out["model"] == model]
    return model, float(rows["r"].mean()), float(rows["rmse_pct_range"].mean())
#: Columns of the NHR and EPOC_norm features in :attr:`FaceData.x`.
_NHR, _EPOC = 2, 3
_DEMOGRAPHICS = ("age", "sex", "height_m", "mass_kg", "training_level")


@dataclasses.dataclass
class GamePredictions:
    """Out-of-fold predicted weights (n, B) of the face rows, and the features the game one saw."""

    as_game: np.ndarray
    nested_measured: np.ndarray
    game_x: np.ndarray


def simulated_features(series: HrSeries, person: pd.Series, regression: object,
                       epoc: EpocParams = EpocParams(), hr_max_formula: str = "tanaka"
                       ) -> tuple[np.ndarray, np.ndarray]:
    """NHR and EPOC_norm at each of the session's ``t_s``, simulated from its work from rest.

    Parameters
    ----------
    series : HrSeries
        One session (its ``t_s`` and ``w_per_kg`` are used; its measured NHR is not).
    person : Series
        The participant's ``age, sex, height_m, mass_kg, training_level``.
    regression : NhrRegression
        The training-level regression (fitted without this participant).
    epoc : EpocParams
        EPOC settings (the training table's).
    hr_max_formula : str
        HR_max formula (does not change NHR or EPOC; needed to build the parameters).

    Returns
    -------
    nhr, epoc_norm : ndarray, shape (len(series.t_s),)
    """
    character = types.SimpleNamespace(**{k: person[k] for k in _DEMOGRAPHICS},
                                      hr_rest_bpm=None, hr_max_bpm=None)
    params = PhysiologyParams.from_character(character, hr_max_formula=hr_max_formula,
                                             regression=regression, epoc=epoc)  # type: ignore[arg-type]
    t = np.asarray(series.t_s, dtype=float)
    grid = t[0] + np.arange(int(round(t[-1] - t[0])) + 1)
    held = np.clip(np.searchsorted(t, grid + 1e-9, side="right") - 1, 0, len(t) - 1)
    w = np.nan_to_num(np.asarray(series.w_per_kg, dtype=float))[held]
    phys = simulate(w, 1.0, params)  # value at grid[k] = after k seconds of work
    at = np.clip(np.round(t - t[0]).astype(int), 0, len(grid) - 1)
    return np.asarray(phys["nhr"])[at], np.asarray(phys["epoc_norm"])[at]


def _game_x(fit: FaceModelFit, test: np.ndarray, series: Sequence[HrSeries], prepared: pd.DataFrame
            ) -> np.ndarray:
    """The test rows' features with NHR and EPOC_norm simulated by a heart model fitted without them."""
    d = fit.data
    held = set(np.unique(d.groups[test]).tolist())
    regression = fit_hr_model([s for s in series if s.participant not in held]).tl_regression.to_nhr_regression()
    people = prepared.drop_duplicates("participant").set_index("participant")
    x, sessions, t_s = d.x[test], d.session[test], d.t_s[test]
    for s in series:
        if s.participant not in held:
            continue
        rows = np.flatnonzero(sessions == s.session)
        if not len(rows):
            continue
        nhr, epoc = simulated_features(s, people.loc[s.participant], regression)
        at = np.searchsorted(np.asarray(s.t_s, dtype=float), t_s[rows])
        at = np.clip(at, 0, len(nhr) - 1)
        x[rows, _NHR], x[rows, _EPOC] = nhr[at], epoc[at]
    return x


def game_predictions(fit: FaceModelFit, series: Sequence[HrSeries], prepared: pd.DataFrame
                     ) -> GamePredictions:
    """Out-of-fold weights as a game gets them, and with measured NHR, both with nested search.

    Parameters
    ----------
    fit : FaceModelFit
        The training run's face fit (its rows, folds and grid).
    series : sequence of HrSeries
        Every session's work and measured NHR (only the other participants' NHR is used).
    prepared : DataFrame
        The prepared table (the participants' demographics).

    Returns
    -------
    GamePredictions
    """
    d, c = fit.data, fit.config
    shape = d.y_norm.shape
    out = GamePredictions(np.full(shape, np.nan), np.full(shape, np.nan), d.x.copy())
    folds = cv_folds(d, "lopo", c.n_splits, c.seed, c.max_folds)
    reuse = c.cv == "lopo" and fit.method == METHODS[1]  # the search's folds are these folds
    for f, ((train, test), inner) in enumerate(zip(folds, nested_choices(d, c, folds))):
        out.game_x[test] = _game_x(fit, test, series, prepared)
        scaler = StandardScaler().fit(d.x[train])
        xs = [scaler.transform(out.game_x[test]), scaler.transform(d.x[test])]
        params = [inner[name] for name in d.blendshapes]
        norm = (search_fit_predictions(fit, f, params, xs) if reuse else
                fit_predict(scaler.transform(d.x[train]), d.y_norm[train], params, fit.method, c.n_landmarks,
                            c.seed, xs))
        e_test = training_expressiveness(d, train, test)
        out.as_game[test] = np.clip(norm[0] * e_test, 0, 1)
        out.nested_measured[test] = np.clip(norm[1] * e_test, 0, 1)
    return out


def game_scores(fit: FaceModelFit, series: Sequence[HrSeries], prepared: pd.DataFrame
                ) -> tuple[pd.DataFrame, GamePredictions]:
    """Per blendshape the ``svr_as_game`` and ``svr_nested_measured_nhr`` held-out metrics.

    Returns
    -------
    scores : DataFrame
        ``blendshape, model, r, rmse_pct_range, rmse_pct_unit, n`` (weight scale), as
        :func:`~effortface.train.face_fit.held_out_scores`.
    predictions : GamePredictions
    """
    pred = game_predictions(fit, series, prepared)
    y = fit.data.y_norm * fit.data.e
    rows = []
    for b, name in enumerate(fit.blendshapes):
        for model, p in zip(GAME_MODELS, (pred.as_game, pred.nested_measured)):
            rows.append({"blendshape": name, "model": model, **weight_metrics(y[:, b], p[:, b])})
    return pd.DataFrame(rows), pred
