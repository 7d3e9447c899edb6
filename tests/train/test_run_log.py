"""The run log's and the comparison's Qt-free helpers (effortface.train.run_log)."""

from __future__ import annotations

import math

from effortface.train.face_fit import GRIDS
from effortface.train.run_log import bundle_settings, cv_caption, eta_s, grid_tooltip, timing_text


def test_eta_is_linear_in_the_fraction_done() -> None:
    assert math.isnan(eta_s(0.0, 5.0))
    assert eta_s(0.25, 10.0) == 30.0
    assert timing_text(0.5, 20.0) == "20 s elapsed, about 20 s left"
    assert timing_text(1.0, 20.0) == "20 s elapsed"


def test_grid_tooltip_lists_every_value() -> None:
    text = grid_tooltip("paper")
    assert "C 0.1, 1, 10, 100" in text and "32 points" in text and "gamma: RBF" in text


def test_bundle_settings_names_the_scheme_and_the_chosen_point() -> None:
    prov = {"cv": "kfold", "rater_policy": "ana", "grid": {k: list(v) for k, v in GRIDS["small"].items()},
            "n_participants": 6}
    met = {"face_cv": {"mouth_open": {"best": {"C": 10.0, "gamma": 0.5, "epsilon": 0.05}}}}
    s = bundle_settings(prov, met)
    assert s["CV scheme"] == "random-frame K-fold (inflated)" and s["grid"] == "small"
    assert s["mouth_open C / gamma / epsilon"] == "10 / 0.5 / 0.05"
    assert bundle_settings({}, {})["CV scheme"] == "not recorded"


def test_one_caption_only_for_one_scheme() -> None:
    assert "both by leave one participant out" in cv_caption("leave one participant out",
                                                             "leave one participant out")
    two = cv_caption("leave one participant out", "random-frame K-fold (inflated)")
    assert "model A by leave one participant out" in two and "model B by random-frame" in two
