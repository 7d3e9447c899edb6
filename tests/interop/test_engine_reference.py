"""The engine reference (docs/ENGINE.md): the shipped test vectors are what the runtime computes,
and a line-by-line transcription of the document's C-like pseudocode reproduces them."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from effortface.interop.engine_reference import VECTORS_NAME, state_vectors, write_vectors

DOCS = Path(__file__).resolve().parents[2] / "docs"


@pytest.fixture(scope="module")
def shipped() -> dict:
    return json.loads((DOCS / VECTORS_NAME).read_text())


def _pseudocode_step(s: dict, p: dict, w_per_kg: float, dt_s: float) -> tuple[float, float, float]:
    """docs/ENGINE.md's effort_step, transcribed statement by statement."""
    s["elapsed_s"] += dt_s
    target = math.floor(s["elapsed_s"] / p["update_period_s"])
    while s["ticks"] < target:
        dt = p["update_period_s"]
        excess = w_per_kg - p["t_root"]
        d_nhr = (p["c_inc"] * excess * (1 - s["nhr"]) * (1 - s["nhr"]) if excess > 0
                 else p["c_dec"] * excess * s["nhr"] * s["nhr"])
        s["nhr"] = min(max(s["nhr"] + dt * d_nhr, 0.0), 1.0)
        intensity = (p["vo2_rest"] + s["nhr"] * (p["vo2max"] - p["vo2_rest"])) / p["vo2max"]
        over = intensity - p["threshold"]
        s["epoc"] = s["epoc"] + dt * p["k_up"] * over * over if over > 0 else s["epoc"] * math.exp(-dt / p["tau_s"])
        s["ticks"] += 1
    return (s["nhr"], p["hr_rest_bpm"] + s["nhr"] * (p["hr_max_bpm"] - p["hr_rest_bpm"]),
            s["epoc"] / p["epoc_scale_ml_per_kg"])


def test_shipped_vectors_are_the_runtime(shipped):
    fresh = state_vectors()
    assert len(shipped["cases"]) == len(fresh["cases"]) == 2
    for old, new in zip(shipped["cases"], fresh["cases"]):
        assert old["params"] == pytest.approx(new["params"], rel=1e-12)
        for key in ("nhr", "hr_bpm", "epoc", "epoc_norm"):
            np.testing.assert_allclose(old[key], new[key], rtol=0, atol=shipped["tolerance"])


def test_pseudocode_reproduces_the_vectors(shipped):
    for case in shipped["cases"]:
        state = {"nhr": 0.0, "epoc": 0.0, "elapsed_s": 0.0, "ticks": 0}
        out = np.array([_pseudocode_step(state, case["params"], w, dt)
                        for w, dt in zip(case["w_per_kg"], case["dt_s"])])
        np.testing.assert_allclose(out[:, 0], case["nhr"], rtol=0, atol=shipped["tolerance"])
        np.testing.assert_allclose(out[:, 1], case["hr_bpm"], rtol=0, atol=shipped["tolerance"])
        np.testing.assert_allclose(out[:, 2], case["epoc_norm"], rtol=0, atol=shipped["tolerance"])


def test_vectors_cover_rise_and_fall(shipped):
    for case in shipped["cases"]:
        nhr, epoc = np.array(case["nhr"]), np.array(case["epoc"])
        assert nhr.max() > 0.5 and nhr[-1] < nhr.max()     # rises under effort, falls after
        assert epoc.max() > 0                               # the EPOC branch is exercised
        assert len(set(np.round(case["dt_s"], 9))) > 3      # jittery frame times


def test_write_vectors_refuses_to_overwrite(tmp_path):
    path = write_vectors(tmp_path / VECTORS_NAME)
    with pytest.raises(FileExistsError, match="refusing to overwrite"):
        write_vectors(path)
    assert json.loads(path.read_text())["format"].startswith("effortface engine state vectors")
