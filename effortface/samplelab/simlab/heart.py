"""An independent heart-rate simulation (deliberately NOT the paper's NHR recursion).

The heart answers the **oxygen demand** of the exercise, with published on- and off-kinetics:

    VO2(t)     = the phase's demand in ml/kg/min (below), through a 2 s lag (a treadmill or a person
                 does not change pace instantly)
    NHR_ss     = (VO2 - 3.5) / (VO2max - 3.5)            %HRR = %VO2R (Swain & Leutholtz 1997)
    HR_ss      = HR_rest + NHR_ss (HR_max - HR_rest)
    dHR/dt     = (HR_ss + S + D - HR) / tau              tau = tau_on_s rising, tau_off_s falling
    dS/dt      = (a_slow (HR_max - HR_rest) max(0, NHR_ss - 0.6) - S) / tau_slow_s

**Demand per phase** (:func:`vo2_demand`): treadmill by the ACSM metabolic equations (walking below
2 m/s: ``3.5 + 0.1 v + 1.8 v grade``, running: ``3.5 + 0.2 v + 0.9 v grade``, v in m/min); standing
1.3 MET; squats 5.0 MET (Compendium of Physical Activities 2011, code 02050, "resistance training,
squats"), raised by half the back load over body mass (choice); jumping jacks 8.0 MET (Compendium
code 02020, "calisthenics, vigorous effort") at 54 a minute, scaled by the pace. 1 MET = 3.5 ml/kg/min.

**Capacity**: VO2max (ml/kg/min) grows with training level and falls with age (choice after ACSM's
norms): ``32 + 3 TL - 0.25 (age - 30) - 4 (female)`` +- 2. So the same exercise takes a smaller share
of a fitter participant's reserve, and the training-level model can beat a pooled one, as in the paper.

**Kinetics** (published ranges): on-kinetics time constants of 25-40 s, faster for fitter people
(HR phase II, e.g. Hughson & Morrissey 1982; Whipp & Ward 1990 for VO2), ``38 - 1.2 TL`` +- 3 s;
recovery (off-kinetics) over one to two minutes, ``72 - 3.5 TL`` +- 6 s (fitter people recover faster:
Imai et al. 1994, Cole et al. 1999), so HR falls by about 20-35 bpm in the first minute; a slow
component above 60 % of the reserve; cardiovascular drift D.

**Day to day** (:class:`DayState`, drawn per session): the resting rate shifts (+-3 bpm, sd), the
capacity by about 6 % (sleep, hydration, the previous day's training), the time constants by +-15 %,
and while exercising the rate drifts upwards (cardiovascular drift, 0.3-1.0 bpm per minute above
30 % of the reserve, relaxing over 5 minutes at rest). The trainer sees one participant's two
sessions as one heart.

``w_scale`` (the demand in W/kg that takes a participant to 63 % of their capacity) is no longer
the heart's: it sets the relative intensity of the face's latent states (:mod:`simlab.expression`).

Beats follow the instantaneous rate with beat-to-beat variability: respiratory sinus arrhythmia
(amplitude falling with effort, at the breathing rate) and AR(1) noise. Fitting the paper's model
on these data is therefore a real test, not a round trip.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from effortface.samplelab.simlab.lab import (
    JUMPING_JACK_REF_PER_MIN, Person, SessionPlan, work_at,
)
from effortface.synth.physiology import hr_max_bpm, hr_rest_bpm

DT_S = 0.1  # integration step
#: capacity: ``w_scale = W_SCALE_W_PER_KG + W_SCALE_PER_TL * TL`` (W/kg of demand), see above
W_SCALE_W_PER_KG = 7.0
W_SCALE_PER_TL = 1.6
#: on-kinetics time constant ``TAU_ON_S - TAU_ON_PER_TL * TL`` (s), 25-40 s
TAU_ON_S = 38.0
TAU_ON_PER_TL = 1.2
#: recovery time constant ``TAU_OFF_S - TAU_OFF_PER_TL * TL`` (s): fitter people recover faster
TAU_OFF_S = 72.0
TAU_OFF_PER_TL = 3.5
#: oxygen cost of standing, squats and jumping jacks (MET; Compendium 2011: 1.3, 02050, 02020)
MET_ML_KG_MIN = 3.5
STANDING_MET = 1.3
SQUATS_MET = 5.0
JUMPING_JACKS_MET = 8.0
#: the slow component starts above this share of the reserve
SLOW_FROM_NHR = 0.6


@dataclasses.dataclass(frozen=True)
class HeartParams:
    """One participant's true heart (recorded in the ground truth)."""

    hr_rest_bpm: float
    hr_max_bpm: float
    w_scale_w_per_kg: float
    vo2max_ml_kg_min: float
    tau_on_s: float
    tau_off_s: float
    slow_amp: float
    tau_slow_s: float
    rsa_frac: float
    ar_sd_frac: float


def heart_params(person: Person, rng: np.random.Generator) -> HeartParams:
    """Draw a participant's heart around the charts: fitter means lower HR and faster recovery."""
    tl = person.training_level
    return HeartParams(
        hr_rest_bpm=round(hr_rest_bpm(person.age, person.sex, tl) + rng.normal(0, 2.5), 1),
        hr_max_bpm=round(hr_max_bpm(person.age) + rng.normal(0, 4.0), 1),
        w_scale_w_per_kg=round(W_SCALE_W_PER_KG + W_SCALE_PER_TL * tl + rng.normal(0, 0.6), 2),
        vo2max_ml_kg_min=round(32.0 + 3.0 * tl - 0.25 * (person.age - 30) - 4.0 * (person.sex == "female")
                               + rng.normal(0, 2.0), 1),
        tau_on_s=round(TAU_ON_S - TAU_ON_PER_TL * tl + rng.uniform(-3, 3), 1),
        tau_off_s=round(TAU_OFF_S - TAU_OFF_PER_TL * tl + rng.uniform(-6, 6), 1),
        slow_amp=round(0.10 - 0.008 * tl + rng.uniform(0, 0.03), 3),
        tau_slow_s=round(200.0 + rng.uniform(-40, 40), 1),
        rsa_frac=round(0.03 + rng.uniform(0, 0.02), 3),
        ar_sd_frac=round(0.012 + rng.uniform(0, 0.006), 4),
    )


@dataclasses.dataclass(frozen=True)
class DayState:
    """How a participant's heart differs on the day of one session (recorded in the ground truth)."""

    hr_rest_shift_bpm: float
    capacity_scale: float
    tau_scale: float
    drift_bpm_per_min: float


def day_state(rng: np.random.Generator) -> DayState:
    """Draw one session's day-to-day variation (see the module docstring)."""
    return DayState(hr_rest_shift_bpm=round(float(rng.normal(0.0, 3.0)), 1),
                    capacity_scale=round(float(np.exp(rng.normal(0.0, 0.06))), 3),
                    tau_scale=round(float(rng.uniform(0.85, 1.15)), 3),
                    drift_bpm_per_min=round(float(rng.uniform(0.3, 1.0)), 2))


#: cardiovascular drift relaxes with this time constant at rest (s)
DRIFT_RELAX_S = 300.0


def vo2_demand(plan: SessionPlan, t_s: np.ndarray) -> np.ndarray:
    """Oxygen demand (ml/kg/min) of the plan at times ``t_s``, stepwise by phase (see the module
    docstring: ACSM equations on the treadmill, Compendium METs for the rest)."""
    out = np.full(np.shape(t_s), STANDING_MET * MET_ML_KG_MIN)
    for ph in plan.phases:
        at = (t_s >= ph.start_s) & (t_s < ph.end_s)
        if ph.exercise == "treadmill":
            v = 60.0 * float(ph.speed_m_s or 0.0)  # m/min
            g = ph.grade_pct / 100.0
            out[at] = (MET_ML_KG_MIN + 0.1 * v + 1.8 * v * g if v < 120.0
                       else MET_ML_KG_MIN + 0.2 * v + 0.9 * v * g)
        elif ph.exercise == "squats":
            out[at] = SQUATS_MET * MET_ML_KG_MIN * (1.0 + 0.5 * ph.load_kg / plan.person.mass_kg)
        elif ph.exercise == "jumping_jacks":
            pace = ph.reps / max(ph.end_s - ph.start_s - 0.6, 1.0) * 60.0 / JUMPING_JACK_REF_PER_MIN
            out[at] = JUMPING_JACKS_MET * MET_ML_KG_MIN * pace
    return out


def simulate_hr(plan: SessionPlan, hp: HeartParams, day: DayState | None = None,
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """True HR on a ``DT_S`` grid: returns ``(t_s, drive_w_per_kg, hr_bpm)`` (drive: see lab.Phase;
    it feeds the face's latent states, the heart itself answers :func:`vo2_demand`)."""
    day = day or DayState(0.0, 1.0, 1.0, 0.0)
    t = np.arange(0.0, plan.duration_s + 5.0, DT_S)
    w = first_order_lag(work_at(plan, t, drive=True), 2.0)
    vo2 = first_order_lag(vo2_demand(plan, t), 2.0)
    rest = hp.hr_rest_bpm + day.hr_rest_shift_bpm
    hrr = hp.hr_max_bpm - rest
    frac = np.clip((vo2 - MET_ML_KG_MIN) / (hp.vo2max_ml_kg_min * day.capacity_scale - MET_ML_KG_MIN),
                   0.0, 1.05)
    target = rest + hrr * frac
    hr = np.empty_like(t)
    hr[0], slow, drift = rest + 3.0, 0.0, 0.0
    for k in range(1, t.size):
        slow += DT_S * (hp.slow_amp * hrr * max(0.0, frac[k] - SLOW_FROM_NHR) - slow) / hp.tau_slow_s
        drift += DT_S * (day.drift_bpm_per_min / 60.0 if frac[k] > 0.3 else -drift / DRIFT_RELAX_S)
        goal = min(target[k] + slow + drift, hp.hr_max_bpm)
        tau = (hp.tau_on_s if goal > hr[k - 1] else hp.tau_off_s) * day.tau_scale
        hr[k] = hr[k - 1] + DT_S * (goal - hr[k - 1]) / tau
    return t, w, hr


def first_order_lag(x: np.ndarray, tau_s: float) -> np.ndarray:
    """``x`` on the ``DT_S`` grid through a first-order lag of ``tau_s`` (a treadmill or a person
    does not change pace instantly)."""
    out = np.empty_like(x)
    out[0] = x[0]
    alpha = DT_S / tau_s
    for k in range(1, x.size):
        out[k] = out[k - 1] + alpha * (x[k] - out[k - 1])
    return out


def normalised(hr: np.ndarray, hp: HeartParams) -> np.ndarray:
    """NHR = (HR - rest) / (max - rest), clipped to [0, 1]."""
    return np.clip((hr - hp.hr_rest_bpm) / (hp.hr_max_bpm - hp.hr_rest_bpm), 0.0, 1.0)


def breathing_rate_per_min(nhr: np.ndarray) -> np.ndarray:
    """Breaths per minute from 14 at rest to 45 at maximum."""
    return 14.0 + 31.0 * nhr


def beat_times(t: np.ndarray, hr: np.ndarray, hp: HeartParams, rng: np.random.Generator,
               ) -> np.ndarray:
    """R-wave times (s) following the true rate with RSA and AR(1) beat-to-beat noise."""
    nhr = normalised(hr, hp)
    resp_phase = 2 * np.pi * np.cumsum(breathing_rate_per_min(nhr) / 60.0) * DT_S
    beats = [float(rng.uniform(0.0, 0.8))]
    ar = 0.0
    while beats[-1] < t[-1] - 2.0:
        k = min(int(beats[-1] / DT_S), t.size - 1)
        calm = 1.0 - 0.8 * nhr[k]  # variability shrinks with effort
        ar = 0.6 * ar + rng.normal(0.0, hp.ar_sd_frac * calm)
        rsa = hp.rsa_frac * calm * np.sin(resp_phase[k])
        beats.append(beats[-1] + 60.0 / hr[k] * (1.0 + rsa + ar))
    return np.array(beats)
