"""Physiology: the paper's NHR recursion, the charts, metabolic estimates, streaming = whole clip."""

from __future__ import annotations

import csv
import dataclasses

import numpy as np
import pytest

from effortface.core.errors import UserError
from effortface.synth import physiology as ph


@dataclasses.dataclass
class Person:
    age: float = 20
    sex: str = "male"
    height_m: float = 1.78
    mass_kg: float = 75
    training_level: float = 7.5
    hr_rest_bpm: float | None = None
    hr_max_bpm: float | None = None


def _run(nhr: float, w: float, seconds: int, tl: float) -> float:
    params = ph.NhrParams.from_training_level(tl)
    for _ in range(seconds):
        nhr = float(ph.nhr_step(nhr, w, params))
    return nhr


def test_running_from_rest_at_tl0_reaches_about_082_in_60s() -> None:
    # SCIENCE.md section 3: running (w about 20 W/kg) from rest at TL 0: NHR about 0.82 at 60 s.
    assert _run(0.0, 20.0, 60, tl=0.0) == pytest.approx(0.82, abs=0.01)


def test_recovery_after_running_at_tl75_drops_about_66_bpm() -> None:
    # Character: male, 20 y, TL 7.5 (chart HR_rest 52, Tanaka HR_max 194). 3 min running at
    # 20 W/kg, then 1 min standing (0.1 W/kg): HR drops by about 66 bpm.
    person = Person()
    params = ph.PhysiologyParams.from_character(person)
    w = np.r_[np.full(180, 20.0), np.full(60, 0.1)]
    hr = ph.simulate(w, 1.0, params)["hr_bpm"]
    assert (params.hr_rest_bpm, params.hr_max_bpm) == (52.0, 194.0)
    assert hr[179] - hr[239] == pytest.approx(66.0, abs=2.0)


def test_hr_stays_within_rest_and_max() -> None:
    rng = np.random.default_rng(0)
    w = np.repeat(rng.uniform(0, 40, 60), 120)  # a minute of random levels, 120 Hz, 1 h
    for tl in (0.0, 3.0, 7.5, 10.0):
        params = ph.PhysiologyParams.from_character(Person(training_level=tl))
        hr = ph.simulate(w, 1 / 4, params)["hr_bpm"]
        assert hr.min() >= params.hr_rest_bpm and hr.max() <= params.hr_max_bpm
        assert hr.max() > params.hr_rest_bpm + 0.5 * (params.hr_max_bpm - params.hr_rest_bpm)


def test_extrapolated_rates_are_floored_at_zero() -> None:
    # A lab regression whose c_inc crosses zero before TL 10 (seen on real fits) must never make
    # NHR fall under effort: the rates are floored at 0, scalar and batched alike, t_root is not.
    steep = ph.NhrRegression(t_root=(8.0, -1.0), c_inc=(0.006, -0.001), c_dec=(0.001, -0.0002))
    at10 = ph.NhrParams.from_training_level(10.0, steep)
    assert (at10.t_root, at10.c_inc, at10.c_dec) == pytest.approx((-2.0, 0.0, 0.0))
    batched = ph.NhrParams.from_training_level(np.array([0.0, 10.0]), steep)
    assert batched.c_inc == pytest.approx([0.006, 0.0]) and batched.c_dec == pytest.approx([0.001, 0.0])
    nhr = 0.3
    for _ in range(60):
        nhr = float(ph.nhr_step(nhr, 20.0, at10))
    assert nhr == pytest.approx(0.3)


def test_constant_work_tends_to_bounds() -> None:
    assert _run(0.0, 30.0, 3600, tl=2.0) > 0.98
    assert _run(1.0, 0.0, 3600, tl=2.0) < 0.05


def test_dt_scaling_matches_per_second_recursion() -> None:
    params = ph.NhrParams.from_training_level(3.0)
    fine = 0.0
    for _ in range(60 * 100):
        fine = float(ph.nhr_step(fine, 15.0, params, dt_s=0.01))
    assert fine == pytest.approx(_run(0.0, 15.0, 60, tl=3.0), abs=0.01)


def test_streaming_equals_whole_clip() -> None:
    rng = np.random.default_rng(1)
    w = np.repeat(rng.uniform(0, 30, 40), 90)  # 120 Hz, 30 s of levels
    params = ph.PhysiologyParams.from_character(Person(training_level=4.0))
    whole = ph.simulate(w, 1 / 120, params)
    state = ph.PhysiologyState(params)
    frames = [state.step(wk, 1 / 120) for wk in w]
    for key, curve in whole.items():
        np.testing.assert_array_equal(curve, [f[key] for f in frames], err_msg=key)


def test_batched_state_equals_single_states() -> None:
    people = [Person(training_level=tl, age=a) for tl, a in [(0, 20), (5, 40), (7.5, 60)]]
    singles = [ph.PhysiologyParams.from_character(p) for p in people]
    batch = ph.PhysiologyState(ph.PhysiologyParams.stack(singles))
    states = [ph.PhysiologyState(p) for p in singles]
    rng = np.random.default_rng(2)
    for _ in range(600):
        w = rng.uniform(0, 30, 3)
        out = batch.step(w, 1 / 30)
        for i, s in enumerate(states):
            assert out["hr_bpm"][i] == pytest.approx(float(s.step(w[i], 1 / 30)["hr_bpm"]), abs=1e-12)


def test_charts_and_formulas() -> None:
    assert ph.hr_max_bpm(30) == pytest.approx(187.0)
    assert ph.hr_max_bpm(30, "fox") == 190.0
    assert ph.hr_max_bpm(30, "gellish") == pytest.approx(186.0)
    # Mid-points of the chart: male 26-35 "good" 62-65; TL 0 is "Poor" (82+ -> 82).
    assert ph.hr_rest_bpm(30, "male", 5.0) == 63.5
    assert ph.hr_rest_bpm(30, "male", 0.0) == 82.0
    assert ph.hr_rest_bpm(30, "male", 5.625) == pytest.approx((63.5 + 58.0) / 2)
    # Jackson 1990: 30 y, male, BMI 75/1.78^2, PA-R 5.
    expected = 56.363 + 1.921 * 5 - 0.381 * 30 - 0.754 * 75 / 1.78 ** 2 + 10.987
    assert ph.vo2max_ml_per_kg_min(30, "male", 1.78, 75, 5) == pytest.approx(expected)
    assert ph.rr_max_per_min(0) == 45 and ph.rr_max_per_min(7.5) == 55


def test_measured_values_override_the_charts() -> None:
    params = ph.PhysiologyParams.from_character(Person(hr_rest_bpm=49, hr_max_bpm=185))
    assert (params.hr_rest_bpm, params.hr_max_bpm) == (49, 185)
    with pytest.raises(UserError, match="hr_max_bpm > hr_rest_bpm"):
        ph.PhysiologyParams.from_character(Person(hr_rest_bpm=190, hr_max_bpm=185))


@pytest.mark.parametrize(("message", "call"), [
    (r"hr_max formula: expected one of tanaka", lambda: ph.hr_max_bpm(30, "astrand")),
])
def test_bad_options(message: str, call) -> None:
    with pytest.raises(UserError, match=message):
        call()


def test_bad_chart_names_the_file(tmp_path) -> None:
    bad = tmp_path / "chart.csv"
    bad.write_text("sex,category,age_18_25\nmale,good,sixty\n")
    with pytest.raises(UserError, match="chart.csv: expected a resting-HR chart"):
        ph.read_resting_hr_chart(bad)


def test_epoc_recursion_magnitudes() -> None:
    # 30 min at 70 %VO2max gives a few tens of ml/kg; it then decays with tau of minutes.
    e = ph.EpocParams()
    epoc = 0.0
    for _ in range(1800):
        epoc = float(ph.epoc_step(epoc, 0.70, e, 1.0))
    assert 20 <= epoc <= 60
    after = epoc
    for _ in range(300):
        after = float(ph.epoc_step(after, 0.2, e, 1.0))
    assert after == pytest.approx(epoc * np.exp(-1.0), rel=1e-9)


def test_nhr_tracks_vo2_reserve_on_mfo(shared_data) -> None:
    """Swain & Leutholtz on the MFO graded test: NHR against %VO2 reserve, r >= 0.9."""
    phys = shared_data / "physiology"
    basal = list(csv.DictReader((phys / "mfo_basal_df.csv").open()))
    test = list(csv.DictReader((phys / "mfo_VO2max_df.csv").open()))
    hr_rest = np.mean([float(r["HR"]) for r in basal])
    vo2_rest = np.mean([float(r["VO2"]) for r in basal])
    hr_max = max(float(r["HR"]) for r in test)
    vo2_max = max(float(r["VO2"]) for r in test)
    incremental = [r for r in test if float(r["Load"]) >= 75.0]  # 75 -> 135 W stages
    nhr = ph.nhr_from_hr_bpm([float(r["HR"]) for r in incremental], hr_rest, hr_max)
    vo2r = (np.array([float(r["VO2"]) for r in incremental]) - vo2_rest) / (vo2_max - vo2_rest)
    assert len(incremental) == 15
    assert np.corrcoef(nhr, vo2r)[0, 1] >= 0.9
    # Our VO2 model maps NHR onto the VO2 reserve linearly: predicted %VO2R equals NHR.
    params = dataclasses.replace(ph.PhysiologyParams.from_character(Person()),
                                 vo2_rest=vo2_rest, vo2max=vo2_max)
    predicted = (ph.derived(nhr, 0.0, params)["vo2"] - vo2_rest) / (vo2_max - vo2_rest)
    assert np.corrcoef(predicted, vo2r)[0, 1] >= 0.9


def test_streaming_equals_whole_clip_with_jittery_dt() -> None:
    rng = np.random.default_rng(5)
    dt = rng.uniform(1 / 90, 1 / 30, 4000)  # a game loop's frame times, about 100 s
    w = np.repeat(rng.uniform(0, 30, 40), 100)
    params = ph.PhysiologyParams.from_character(Person(training_level=6.0))
    whole = ph.simulate(w, dt, params)
    state = ph.PhysiologyState(params)
    frames = [state.step(wk, dk) for wk, dk in zip(w, dt)]
    assert state.ticks == int(np.sum(dt))
    for key, curve in whole.items():
        np.testing.assert_array_equal(curve, [f[key] for f in frames], err_msg=key)
