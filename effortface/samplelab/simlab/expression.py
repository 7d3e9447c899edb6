"""True blendshape curves from the simulator's own latent states, after the paper's empirical rules
(SCIENCE.md section 6), scaled by the participant's expressiveness.

The latent states are deliberately not the trainer's features (w, p, NHR and its history): they run
on the **relative intensity** ``rel = 1 - exp(-demand / capacity)`` (demand: lab.Phase; capacity:
the heart's ``w_scale`` on that day, unknown to the trainer) and on the repetitions' timing:

- **exertion**: a latent with its own dynamics, rising in 3 s and falling in 8 s towards
  ``0.85 rel^1.2`` plus the **muscular strain** of each repetition (pulses scaled by displaced mass
  over working-muscle mass: lab.strain_at) plus a slow motivation term (Ornstein-Uhlenbeck, sd 0.06,
  30 s);
- **fatigue**: an anaerobic reserve (W'-balance form, Skiba-like): above a critical intensity
  ``0.55 + 0.02 TL`` the reserve drains, below it refills with a time constant that grows with the
  depth of the deficit and shrinks with training level; three quarters of the fatigue is the
  reserve spent, one quarter a slow metabolic accumulation (energy spent in the session);
- **ventilation**: follows the relative intensity in about 40 s, plus fatigue; it sets the breathing
  rate (14-45 /min);
- ``mouth_stretch``: exertion and fatigue;
- ``mouth_open``: closed until ventilation passes about 45 %, then opens with the breathing rhythm
  and fatigue; quick expirations and gulps at rates growing with fatigue and breathing rate; during
  a strength set the mouth opens to breathe out on each repetition's effort (the set's strain
  through a lag of 2 s up and 6 s down, rippling with the repetitions);
- ``eye_squint``: exertion up to a fatigue level, then relaxes with fatigue to a residual;
- ``brow_lower``: down with exertion, up with fatigue.
"""

from __future__ import annotations

import numpy as np

from effortface.samplelab.simlab.heart import DT_S, DayState, HeartParams, first_order_lag
from effortface.samplelab.simlab.lab import SessionPlan, strain_at

NAMES = ("mouth_stretch", "mouth_open", "eye_squint", "brow_lower")
#: W'-balance reserve in relative-intensity seconds (choice: 100 s at 25 % above the critical intensity)
RESERVE_REL_S = 25.0


def relative_intensity(drive: np.ndarray, hp: HeartParams, day: DayState) -> np.ndarray:
    """The share of the participant's capacity that day: ``1 - exp(-demand / capacity)``."""
    return 1.0 - np.exp(-drive / (hp.w_scale_w_per_kg * day.capacity_scale))


def _asymmetric_lag(x: np.ndarray, tau_up_s: float, tau_down_s: float) -> np.ndarray:
    out = np.empty_like(x)
    out[0] = x[0]
    for k in range(1, x.size):
        tau = tau_up_s if x[k] > out[k - 1] else tau_down_s
        out[k] = out[k - 1] + DT_S * (x[k] - out[k - 1]) / tau
    return out


def _ou(n: int, sd: float, tau_s: float, rng: np.random.Generator) -> np.ndarray:
    """An Ornstein-Uhlenbeck path (stationary sd ``sd``, time constant ``tau_s``)."""
    a = np.exp(-DT_S / tau_s)
    steps = rng.normal(0.0, sd * np.sqrt(1 - a * a), n)
    out = np.empty(n)
    out[0] = rng.normal(0.0, sd)
    for k in range(1, n):
        out[k] = a * out[k - 1] + steps[k]
    return out


def _reserve_fatigue(rel: np.ndarray, training_level: float) -> np.ndarray:
    """1 - W' balance: drains above the critical intensity, refills below it."""
    critical = 0.55 + 0.02 * training_level
    spent = np.empty_like(rel)
    spent[0], deepest = 0.0, 0.0
    for k in range(1, rel.size):
        excess = rel[k] - critical
        if excess > 0:
            spent[k] = min(RESERVE_REL_S, spent[k - 1] + DT_S * excess)
            deepest = max(deepest, spent[k])
        else:  # recovery is slower after a deeper deficit and faster for trained people
            tau = (60.0 + 10.0 * (7.5 - training_level)) * (1.0 + deepest / RESERVE_REL_S)
            spent[k] = spent[k - 1] * np.exp(-DT_S / tau)
            deepest = spent[k] if spent[k] < 0.05 * RESERVE_REL_S else deepest
    return spent / RESERVE_REL_S


def drivers(plan: SessionPlan, grid_t: np.ndarray, drive: np.ndarray, nhr: np.ndarray, hp: HeartParams,
            day: DayState, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """Exertion, fatigue, ventilation, strain and breathing phase on the simulation grid."""
    tl = plan.person.training_level
    rel = relative_intensity(drive, hp, day)
    strain = strain_at(plan, grid_t)
    target = 0.85 * rel ** 1.2 + 0.6 * strain + _ou(rel.size, 0.06, 30.0, rng)
    exertion = np.clip(_asymmetric_lag(np.clip(target, 0.0, 1.0), 3.0, 8.0), 0.0, 1.0)
    metabolic = 1.0 - np.exp(-np.cumsum(rel) * DT_S / (900.0 + 60.0 * tl))
    fatigue = np.clip(0.75 * _reserve_fatigue(rel, tl) + 0.25 * metabolic, 0.0, 1.0)
    ventilation = np.clip(first_order_lag(rel, 40.0) + 0.25 * fatigue, 0.0, 1.0)
    breath = 2 * np.pi * np.cumsum((14.0 + 31.0 * ventilation) / 60.0) * DT_S
    return {"exertion": exertion, "fatigue": fatigue, "ventilation": ventilation, "strain": strain,
            "relative_intensity": rel, "breath_phase": breath, "nhr": nhr}


def _bursts(rate_per_s: np.ndarray, length_s: float, rng: np.random.Generator) -> np.ndarray:
    """Short pulses (``length_s``) starting at ``rate_per_s``."""
    starts = rng.random(rate_per_s.size) < rate_per_s * DT_S
    kernel = np.hanning(int(length_s / DT_S) + 2)[1:-1]
    return np.clip(np.convolve(starts.astype(float), kernel)[:rate_per_s.size], 0.0, 1.0)


def true_curves(d: dict[str, np.ndarray], expressiveness: tuple[float, ...],
                rng: np.random.Generator) -> np.ndarray:
    """The four true weights on the simulation grid, shape ``(n, 4)``, in [0, 1]."""
    ex, fa, ve = d["exertion"], d["fatigue"], d["ventilation"]
    breaths_per_s = (14.0 + 31.0 * ve) / 60.0
    breathing = 0.5 + 0.5 * np.sin(d["breath_phase"])
    opens = 1.0 / (1.0 + np.exp(-(ve - 0.45) / 0.07))  # closed early, opens with ventilation
    expirations = _bursts(fa * breaths_per_s / 8.0, 0.6, rng)  # up to one in 8 breaths when spent
    gulps = _bursts(fa * breaths_per_s / 20.0, 0.4, rng)
    set_breath = _asymmetric_lag(np.clip(3.0 * d["strain"], 0.0, 1.0), 2.0, 6.0)
    raw = np.column_stack([
        0.7 * ex + 0.35 * fa,
        opens * (0.45 + 0.35 * fa) * (0.7 + 0.3 * breathing) * (1.0 - 0.6 * gulps) + 0.35 * expirations
        + 0.45 * set_breath * (0.6 + 0.4 * breathing),
        ex * (1.0 - 0.55 * fa) + 0.15 * fa,
        0.9 * ex * (1.0 - 0.5 * fa),
    ])
    return np.clip(raw * np.asarray(expressiveness)[None, :], 0.0, 1.0)


def at_times(grid_t: np.ndarray, values: np.ndarray, t_s: np.ndarray) -> np.ndarray:
    """Linear interpolation of grid columns at times ``t_s``."""
    return np.column_stack([np.interp(t_s, grid_t, values[:, j]) for j in range(values.shape[1])])
