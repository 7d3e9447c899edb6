"""One bounds table for every number a file or an option can carry (stdlib only: the runtime uses it).

A finite but absurd value (a gamma of 1e308, a body mass of 1e308 kg, an update period of 1e-300 s,
a heart-rate time of 1e12 s) makes NaN output, a stalled game loop or a 7 TiB allocation, so every
reader and every CLI option checks its numbers here, by name, before use. The limits are wide: they
refuse only what no lab or game can mean, never a plausible measurement.

Each entry: ``name -> Bound(low, high, unit, low_open)``; ``low_open`` excludes ``low`` itself.
"""

from __future__ import annotations

import dataclasses
import math
import numbers

from effortface.core.errors import UserError
from effortface.core.participant import LIMITS


@dataclasses.dataclass(frozen=True)
class Bound:
    """Accepted range of one quantity: ``low <= x <= high`` (``low < x`` when ``low_open``)."""

    low: float
    high: float
    unit: str = ""
    low_open: bool = False

    def describe(self) -> str:
        """``'a number above 0 and at most 300 kg'`` or ``'a number from 0 to 500 kg'``."""
        unit = f" {self.unit}" if self.unit else ""
        if self.low_open:
            return f"a number above {self.low:g} and at most {self.high:g}{unit}"
        return f"a number from {self.low:g} to {self.high:g}{unit}"

    def contains(self, value: float) -> bool:
        """True when ``value`` lies in the range (NaN never does)."""
        above = value > self.low if self.low_open else value >= self.low
        return bool(above and value <= self.high)


#: every bounded quantity, by the name used in files and messages
BOUNDS: dict[str, Bound] = {
    # people and loads: a body mass has the participant table's ceiling (taken from
    # effortface.core.participant.LIMITS, 300 kg); loads above 500 kg cannot be carried
    "mass_kg": Bound(0.0, LIMITS["mass_kg"].bounds[1], "kg", low_open=True),
    "load_kg": Bound(0.0, 500.0, "kg"),
    "unit_m": Bound(0.0, 100.0, "m", low_open=True),
    # session times: 0 is the recording start; 1e6 s is 11.6 days of recording
    "t_s": Bound(0.0, 1e6, "s"),
    "offset_s": Bound(-1e6, 1e6, "s"),
    # model.json: the SVR and its standardisation
    "C": Bound(0.0, 1e6, "", low_open=True),
    "gamma": Bound(0.0, 1e6, "", low_open=True),
    "epsilon": Bound(0.0, 10.0, "", low_open=True),
    "scaler_mean": Bound(-1e6, 1e6, ""),
    "scaler_scale": Bound(1e-9, 1e6, ""),
    "svr_value": Bound(-1e9, 1e9, ""),
    # model.json: heart-rate coefficients (t_root, c_inc, c_dec; their TL lines within +-high)
    "nhr_coefficient": Bound(0.0, 1e6, "", low_open=True),
    # model.json: physiology (1 ms to 1 min per update: one game frame to a coarse simulation)
    "update_period_s": Bound(1e-3, 60.0, "s"),
    "k_up": Bound(0.0, 1e3, "ml/kg/s", low_open=True),
    "tau_s": Bound(0.0, 1e6, "s", low_open=True),
    "scale_ml_per_kg": Bound(0.0, 1e6, "ml/kg", low_open=True),
    # live input (serve) and motion files: work and power per kg (a sprint peaks near 25 W/kg) and
    # joint positions (a capture volume is tens of metres; 1 km is no body)
    "w_per_kg": Bound(-1e3, 1e3, "W/kg"),
    "p_per_kg": Bound(-1e3, 1e3, "W/kg"),
    "position_m": Bound(-1e3, 1e3, "m"),
    # motion files: a BVH frame time (10 kHz to one frame in 10 s) and a clip's frame rate
    "frame_time_s": Bound(1e-4, 10.0, "s"),
    "motion_fps": Bound(0.1, 1e4, "Hz"),
    # options of the live server
    "fps": Bound(0.0, 1000.0, "Hz", low_open=True),
    "report_s": Bound(0.0, 3600.0, "s", low_open=True),
    "port": Bound(0.0, 65535.0, ""),
    # blendshape weights and scores (key-frames, ratings, the machine rater's track)
    "blendshape_weight": Bound(0.0, 1.0, ""),
    # video frame numbers (annotation keys, poses): 1e9 frames is 385 days at 30 fps
    "frame": Bound(0.0, 1e9, ""),
    # model.json: the output filter's time constants (0: off; an hour smooths away any effort)
    "filter_tau_s": Bound(0.0, 3600.0, "s"),
    # model.json: the SVR's normalised output at rest (rest_anchor.at_rest; train writes it clipped to
    # [0, 0.99]); far below 0 it maps every output to 1 (-1e300: weight 1.0 on every frame)
    "rest_at_rest": Bound(-1.0, 0.99, ""),
    "rest_level": Bound(0.0, 0.99, ""),
    # session.json: counts of frames, samples, bytes, pixels
    "count": Bound(0.0, 1e15, ""),
}


def check(name: str, value: object, where: str = "") -> float:
    """Return ``value`` as a float if it is a number within ``BOUNDS[name]``, else raise.

    Parameters
    ----------
    name : str
        A key of :data:`BOUNDS`.
    value : object
        The number read from a file or an option (a bool or a string is refused).
    where : str
        What holds it, for the message (``"--mass"``, ``"model.json: svr[0].gamma"``); ``name`` if
        empty.

    Returns
    -------
    float

    Raises
    ------
    UserError
        One line: where, the accepted range and the value found.
    """
    bound = BOUNDS[name]
    label = where or name
    number = _as_float(value)
    if not bound.contains(number):
        shown = f"{number:g}" if isinstance(value, float) else f"{value!r:.40}"
        raise UserError(f"{label}: expected {bound.describe()}, found {shown}")
    return number


def _as_float(value: object) -> float:
    """``value`` as a float; NaN for a non-number or a bool, infinity for an int beyond float range."""
    if not isinstance(value, numbers.Real) or isinstance(value, bool):
        return math.nan
    try:
        return float(value)
    except OverflowError:  # an int beyond float range
        return -math.inf if str(value).startswith("-") else math.inf


def is_number(text: str) -> bool:
    """True if ``text`` parses as a float (``"1e3"``, ``"nan"`` and ``"-0.5"`` do; ``"12a"`` does not).

    Parameters
    ----------
    text : str
        A field of a file being read.

    Returns
    -------
    bool
    """
    try:
        float(text)
    except ValueError:
        return False
    return True
