"""True blendshape curves from the simulated physiology, after the paper's empirical rules
(SCIENCE.md section 6), scaled by the participant's expressiveness:

- exertion follows mechanical power (a fast first-order response to the work rate);
- fatigue accumulates while HR is high and recovers slowly, faster for trained people;
- ``mouth_stretch``: exertion and fatigue;
- ``mouth_open``: closed early, then opens with breathing (the breathing rhythm shows) and fatigue,
  with occasional quick expirations whose frequency grows with fatigue;
- ``eye_squint``: exertion up to a fatigue level, then relaxes with fatigue to a residual;
- ``brow_lower``: down with exertion, up with fatigue.
"""

from __future__ import annotations

import numpy as np

from effortface.samplelab.simlab.heart import DT_S, breathing_rate_per_min, first_order_lag

EXERTION_SCALE_W_PER_KG = 9.0
NAMES = ("mouth_stretch", "mouth_open", "eye_squint", "brow_lower")


def drivers(w: np.ndarray, nhr: np.ndarray, training_level: float) -> dict[str, np.ndarray]:
    """Exertion, fatigue and breathing on the simulation grid (all in [0, 1] but breathing)."""
    exertion = first_order_lag(1.0 - np.exp(-w / EXERTION_SCALE_W_PER_KG), 1.5)
    fatigue = np.empty_like(nhr)
    fatigue[0] = 0.0
    tau_rec_s = 60.0 + 12.0 * (7.5 - training_level)
    for k in range(1, nhr.size):
        load = 0.012 * max(0.0, nhr[k] - 0.45)
        fatigue[k] = fatigue[k - 1] + DT_S * (load * (1.0 - fatigue[k - 1]) - fatigue[k - 1] / tau_rec_s)
    fatigue = np.clip(fatigue / 0.35, 0.0, 1.0)
    breath = 2 * np.pi * np.cumsum(breathing_rate_per_min(nhr) / 60.0) * DT_S
    return {"exertion": exertion, "fatigue": fatigue, "breath_phase": breath, "nhr": nhr}


def _expirations(n: int, fatigue: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Short bursts (about 0.6 s) at a rate growing with fatigue, up to one per 12 s."""
    rate_per_step = fatigue * DT_S / 12.0
    starts = rng.random(n) < rate_per_step
    kernel = np.hanning(int(0.6 / DT_S) + 2)[1:-1]
    return np.clip(np.convolve(starts.astype(float), kernel)[:n], 0.0, 1.0)


def true_curves(d: dict[str, np.ndarray], expressiveness: tuple[float, ...],
                rng: np.random.Generator) -> np.ndarray:
    """The four true weights on the simulation grid, shape ``(n, 4)``, in [0, 1]."""
    ex, fa, nhr = d["exertion"], d["fatigue"], d["nhr"]
    breathing = 0.5 + 0.5 * np.sin(d["breath_phase"])
    opens = 1.0 / (1.0 + np.exp(-(nhr - 0.5) / 0.07))  # closed early, opens past ~50 % HRR
    raw = np.column_stack([
        0.7 * ex + 0.35 * fa,
        opens * (0.45 + 0.35 * fa) * (0.7 + 0.3 * breathing) + 0.35 * _expirations(nhr.size, fa, rng),
        ex * (1.0 - 0.55 * fa) + 0.15 * fa,
        0.9 * ex * (1.0 - 0.5 * fa),
    ])
    return np.clip(raw * np.asarray(expressiveness)[None, :], 0.0, 1.0)


def at_times(grid_t: np.ndarray, values: np.ndarray, t_s: np.ndarray) -> np.ndarray:
    """Linear interpolation of grid columns at times ``t_s``."""
    return np.column_stack([np.interp(t_s, grid_t, values[:, j]) for j in range(values.shape[1])])
