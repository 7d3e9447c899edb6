"""An independent heart-rate simulation (deliberately NOT the paper's NHR recursion).

First-order kinetics towards a steady state set by the metabolic demand, with a slow component,
then beats:

    HR_ss(d)   = HR_rest + 0.95 (HR_max - HR_rest) (1 - exp(-d / w_scale))
    dHR/dt     = (HR_ss + S - HR) / tau        tau = tau_on_s when rising, tau_off_s when falling
    dS/dt      = (a_slow (HR_max - HR_rest) max(0, f(d) - 0.5) - S) / tau_slow_s

**Demand d (choice).** The heart answers the metabolic demand of the exercise, not its mechanical
work: d is the work rate times a demand factor per kind of exercise (``lab.Phase.drive_w_per_kg``:
1 for walking and running, 1.8 for squats times (1 + back load / body mass), 1.2 for jumping jacks),
the same for everyone. What differs between people is their **capacity**: ``w_scale``, the demand
that takes HR to 60 % of the reserve, grows with training level (7 + 1.6 TL W/kg, as VO2max does:
a fitter heart pumps more per beat, so the same exercise takes a smaller share of its reserve),
and recovery is faster for fitter people (``tau_off`` 80 - 7 TL s). So a participant's fitted
threshold reflects their fitness whichever kind of exercise they did, and the training-level model
can beat a pooled one, as in the paper.

**Day to day** (:class:`DayState`, drawn per session): the resting rate shifts (+-3 bpm, sd), the
capacity by about 6 % (sleep, hydration, the previous day's training), the time constants by +-15 %,
and while exercising the rate drifts upwards (cardiovascular drift, 0.3-1.0 bpm per minute above
30 % of the reserve, relaxing over 5 minutes at rest). The trainer sees one participant's two
sessions as one heart.

Beats follow the instantaneous rate with beat-to-beat variability: respiratory sinus arrhythmia
(amplitude falling with effort, at the breathing rate) and AR(1) noise. Fitting the paper's model
on these data is therefore a real test, not a round trip.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from effortface.samplelab.simlab.lab import Person, SessionPlan, work_at
from effortface.train.physiology import hr_max_bpm, hr_rest_bpm

DT_S = 0.1  # integration step
#: capacity: ``w_scale = W_SCALE_W_PER_KG + W_SCALE_PER_TL * TL`` (W/kg of demand), see above
W_SCALE_W_PER_KG = 7.0
W_SCALE_PER_TL = 1.6
#: recovery time constant ``TAU_OFF_S - TAU_OFF_PER_TL * TL`` (s): fitter people recover faster
TAU_OFF_S = 80.0
TAU_OFF_PER_TL = 7.0


@dataclasses.dataclass(frozen=True)
class HeartParams:
    """One participant's true heart (recorded in the ground truth)."""

    hr_rest_bpm: float
    hr_max_bpm: float
    w_scale_w_per_kg: float
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
        tau_on_s=round(22.0 + rng.uniform(-4, 6), 1),
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


def simulate_hr(plan: SessionPlan, hp: HeartParams, day: DayState | None = None,
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """True HR on a ``DT_S`` grid: returns ``(t_s, drive_w_per_kg, hr_bpm)`` (drive: see lab.Phase)."""
    day = day or DayState(0.0, 1.0, 1.0, 0.0)
    t = np.arange(0.0, plan.duration_s + 5.0, DT_S)
    w = first_order_lag(work_at(plan, t, drive=True), 2.0)
    rest = hp.hr_rest_bpm + day.hr_rest_shift_bpm
    hrr = hp.hr_max_bpm - rest
    frac = 1.0 - np.exp(-w / (hp.w_scale_w_per_kg * day.capacity_scale))
    target = rest + 0.95 * hrr * frac
    hr = np.empty_like(t)
    hr[0], slow, drift = rest + 3.0, 0.0, 0.0
    for k in range(1, t.size):
        slow += DT_S * (hp.slow_amp * hrr * max(0.0, frac[k] - 0.5) - slow) / hp.tau_slow_s
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
