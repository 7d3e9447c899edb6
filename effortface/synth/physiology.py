"""Physiology from mechanical work: NHR recursion, heart rate, VO2, respiration rate and EPOC.

SCIENCE.md sections 3 and 4 are the specification. Everything here is numpy only (the runtime
imports it) and works on scalars or on arrays of characters alike: every parameter of
:class:`PhysiologyParams` may be a float or an array of shape ``(N,)``, and the state then holds
``N`` characters stepped together.

Two paths give identical curves (tested):

- :class:`PhysiologyState` streams: ``state.step(w_per_kg, dt_s)`` once per frame. Frames
  accumulate time and the recursion runs once per ``update_period_s`` of simulated time (1 s, the
  paper's rate) with ``dt = update_period_s``.
- :func:`simulate` takes a whole clip's work curve and runs the same per-second recursion on the
  tick frames only, then broadcasts the result to every frame with numpy.

Choices (SCIENCE.md marks them (choice)) are named parameters with defaults documented below.
"""

from __future__ import annotations

import csv
import dataclasses
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from effortface.core import bounds
from effortface.core.errors import UserError

#: The resting-HR chart shipped with the package (copied from ../shared/data/tables).
CHART_PATH = Path(__file__).resolve().parent / "data" / "resting_hr_chart.csv"

#: HR_max = a - b * age (bpm). Tanaka 2001 is the default; Fox and Gellish are options.
HR_MAX_FORMULAS: dict[str, tuple[float, float]] = {
    "tanaka": (208.0, 0.7),
    "fox": (220.0, 1.0),
    "gellish": (207.0, 0.7),
}

#: Chart categories in increasing fitness; TL = 1.25 * index (choice: TL 0 Poor ... 7.5 Athlete).
CHART_CATEGORIES = ("poor", "below_average", "average", "above_average", "good", "excellent",
                    "athlete")
TL_PER_CATEGORY = 1.25
#: Upper age of each chart band (the last band, 65+, is open).
_AGE_BAND_UPPER = (25, 35, 45, 55, 65, math.inf)

#: Resting VO2 (ml/kg/min), 1 MET (Swain & Leutholtz 1997 use it for %VO2 reserve).
VO2_REST_ML_PER_KG_MIN = 3.5
#: Respiration rate at rest and at maximum (breaths/min); RR_max rises with TL (choice).
RR_REST_PER_MIN = 14.0
RR_MAX_TL0_PER_MIN = 45.0
RR_MAX_TL75_PER_MIN = 55.0


class _PersonLike(Protocol):
    """What physiology needs of a character (runtime.Character has it)."""

    @property
    def age(self) -> float: ...
    @property
    def sex(self) -> str: ...
    @property
    def height_m(self) -> float: ...
    @property
    def mass_kg(self) -> float: ...
    @property
    def training_level(self) -> float: ...
    @property
    def hr_rest_bpm(self) -> float | None: ...
    @property
    def hr_max_bpm(self) -> float | None: ...


# --------------------------------------------------------------------------- charts and formulas

def hr_max_bpm(age: float, formula: str = "tanaka") -> float:
    """Age-predicted maximal heart rate.

    Parameters
    ----------
    age : float
        Age in years.
    formula : {"tanaka", "fox", "gellish"}
        Tanaka 2001 ``208 - 0.7 age`` (default), Fox ``220 - age``, Gellish ``207 - 0.7 age``.

    Returns
    -------
    float
        HR_max in bpm.

    Raises
    ------
    UserError
        If ``formula`` is unknown.
    """
    if formula not in HR_MAX_FORMULAS:
        raise UserError(f"hr_max formula: expected one of {', '.join(HR_MAX_FORMULAS)}, "
                        f"found {formula!r}")
    a, b = HR_MAX_FORMULAS[formula]
    return a - b * float(age)


def _cell_bpm(cell: str) -> float:
    """Mid-point of a chart cell such as '62-65'; an open cell '82+' gives its bound."""
    cell = cell.strip()
    if cell.endswith("+"):
        return float(cell[:-1])
    low, high = cell.split("-")
    return (float(low) + float(high)) / 2.0


def read_resting_hr_chart(path: str | Path = CHART_PATH) -> dict[tuple[str, str], tuple[float, ...]]:
    """Read the resting-HR chart (csv module; '#' lines are comments).

    Parameters
    ----------
    path : str or Path
        The chart CSV: ``sex,category,age_18_25,...,age_65_plus`` with cells ``low-high`` or ``low+``.

    Returns
    -------
    dict
        ``(sex, category) -> mid-point bpm per age band`` (six bands).

    Raises
    ------
    UserError
        If the file is missing or a row is malformed.
    """
    path = Path(path)
    try:
        lines = [ln for ln in path.read_text(encoding="utf-8").splitlines()
                 if ln.strip() and not ln.startswith("#")]
        rows = list(csv.DictReader(lines))
        chart = {(r["sex"], r["category"]): tuple(_cell_bpm(v) for k, v in r.items()
                                                  if k.startswith("age_"))
                 for r in rows}
    except (OSError, KeyError, ValueError, AttributeError, csv.Error) as exc:
        raise UserError(f"{path}: expected a resting-HR chart (sex,category,age_...), "
                        f"found {exc!r}") from None
    return chart


_CHART_CACHE: dict[str, dict[tuple[str, str], tuple[float, ...]]] = {}


def _default_chart() -> dict[tuple[str, str], tuple[float, ...]]:
    if "default" not in _CHART_CACHE:
        _CHART_CACHE["default"] = read_resting_hr_chart()
    return _CHART_CACHE["default"]


def _age_band(age: float) -> int:
    """Index of the chart's age band; under-18s use the 18-25 band (choice)."""
    return next(i for i, upper in enumerate(_AGE_BAND_UPPER) if age < upper + 1)


def hr_rest_bpm(age: float, sex: str, training_level: float,
                chart: Mapping[tuple[str, str], tuple[float, ...]] | None = None) -> float:
    """Resting heart rate from the chart by sex, age band and training level.

    TL is mapped onto the chart's categories (TL 0 = Poor, 1.25 = Below average, ... 7.5 = Athlete)
    and interpolated linearly between the categories' mid-points; TL above 7.5 stays Athlete.

    Parameters
    ----------
    age : float
        Age in years.
    sex : {"male", "female"}
        Sex, as in the chart.
    training_level : float
        Training level (0 ... 7.5 on the chart; clamped to it).
    chart : mapping, optional
        A chart from :func:`read_resting_hr_chart`; the packaged one by default.

    Returns
    -------
    float
        HR_rest in bpm.

    Raises
    ------
    UserError
        If ``sex`` is not in the chart.
    """
    chart = _default_chart() if chart is None else chart
    sexes = sorted({k[0] for k in chart})
    if sex not in sexes:
        raise UserError(f"sex: expected one of {', '.join(sexes)} (resting-HR chart), found {sex!r}")
    band = _age_band(float(age))
    bpm = [chart[(sex, cat)][band] for cat in CHART_CATEGORIES]
    tls = [i * TL_PER_CATEGORY for i in range(len(CHART_CATEGORIES))]
    return float(np.interp(float(training_level), tls, bpm))


def vo2max_ml_per_kg_min(age: float, sex: str, height_m: float, mass_kg: float,
                         training_level: float) -> float:
    """VO2max from the Jackson et al. 1990 non-exercise model.

    ``56.363 + 1.921 PA-R - 0.381 age - 0.754 BMI + 10.987 male``, with PA-R = min(TL, 7).

    Returns
    -------
    float
        VO2max in ml/kg/min.

    Raises
    ------
    UserError
        If a value is missing, not finite, or (except TL) not positive.
    """
    for name, value in (("age", age), ("height_m", height_m), ("mass_kg", mass_kg),
                        ("training_level", training_level)):
        if value is None or not np.isfinite(float(value)) or (name != "training_level" and value <= 0):
            raise UserError(f"{name}: expected a positive number for VO2max, found {value!r}")
    bmi = mass_kg / height_m ** 2
    par = min(float(training_level), 7.0)
    male = 1.0 if sex == "male" else 0.0
    return 56.363 + 1.921 * par - 0.381 * age - 0.754 * bmi + 10.987 * male


def rr_max_per_min(training_level: float) -> float:
    """Maximal respiration rate: 45 (TL 0) to 55 (TL 7.5) breaths/min, clamped (choice)."""
    frac = min(max(float(training_level) / 7.5, 0.0), 1.0)
    return RR_MAX_TL0_PER_MIN + frac * (RR_MAX_TL75_PER_MIN - RR_MAX_TL0_PER_MIN)


# --------------------------------------------------------------------------- NHR recursion

#: METs of the reference activities (2024 Adult Compendium of Physical Activities, Herrmann et al.
#: 2024; activity, Compendium description) used to calibrate the built-in model. See
#: docs/SCIENCE_NOTES.md for the codes and for cycling, which is not calibrated through w.
COMPENDIUM_METS: dict[str, float] = {
    "standing": 1.3,        # standing quietly
    "squats": 3.8,          # calisthenics (e.g. squats, lunges), moderate effort
    "walking": 4.0,         # walking 3.4 mph (1.5 m/s), level, firm surface (3.5 @ 3.0, 4.3 @ 3.5 mph)
    "jumping jacks": 8.0,   # calisthenics (e.g. jumping jacks), vigorous effort
    "running": 11.8,        # running 7.5 mph (3.4 m/s)
}


@dataclasses.dataclass(frozen=True)
class MetCurve:
    """Metabolic rate (METs) of steady activity as a function of the work w (W/kg).

    ``METs(w) = met_at_rest + met_per_w * w ** exponent``, fitted by least squares to the
    Compendium METs of the reference clips (:data:`COMPENDIUM_METS`) against their measured w
    (:func:`fit_met_curve`). Through Swain's %VO2R = %HRR it gives the NHR a steady activity
    holds: ``NHR_ss = (METs(w) - 1) / (VO2max / 3.5 - 1)``.
    """

    met_at_rest: float = 1.3
    met_per_w: float = 1.156
    exponent: float = 0.735

    def mets(self, w_per_kg: Any) -> np.ndarray:
        """METs of steady work ``w_per_kg`` (W/kg, >= 0)."""
        return self.met_at_rest + self.met_per_w * np.maximum(np.asarray(w_per_kg, float), 0.0) ** self.exponent

    def hold_w_per_kg(self, nhr: Any, reserve_mets: Any) -> np.ndarray:
        """Work (W/kg) that holds ``nhr`` steady: METs(w) = 1 + NHR * reserve (0 below standing's NHR).

        ``reserve_mets`` is the character's VO2 reserve in METs, ``VO2max / 3.5 - 1``.
        """
        extra = 1.0 + np.asarray(nhr, float) * reserve_mets - self.met_at_rest
        return (np.maximum(extra, 0.0) / self.met_per_w) ** (1.0 / self.exponent)


def fit_met_curve(w_per_kg: Any, mets: Any, met_at_rest: float = COMPENDIUM_METS["standing"]) -> MetCurve:
    """Least-squares fit of ``METs = met_at_rest + a w^b`` (a, b) to activities' work and METs.

    Parameters
    ----------
    w_per_kg, mets : array_like, shape (n,)
        Measured work of each reference clip (W/kg) and its Compendium METs.
    met_at_rest : float
        METs at w = 0 (standing quietly, 1.3).

    Returns
    -------
    MetCurve
    """
    from scipy.optimize import curve_fit  # only the calibration needs it, not the runtime

    w, y = np.asarray(w_per_kg, float), np.asarray(mets, float)
    (a, b), _ = curve_fit(lambda x, a, b: met_at_rest + a * x ** b, w, y, p0=(1.0, 0.8))
    return MetCurve(met_at_rest, float(a), float(b))


@dataclasses.dataclass(frozen=True)
class NhrRegression:
    """Linear regressions of the NHR coefficients on training level: ``(intercept, slope)`` each.

    The defaults are the paper's fit; the training stage plugs in its own. ``met_curve`` (None
    for the paper and for trained bundles) adds the work needed to hold the current NHR to the
    threshold (see :meth:`NhrParams.threshold_w_per_kg`): the Compendium-calibrated built-in model.
    """

    t_root: tuple[float, float] = (7.13, 0.42)
    c_inc: tuple[float, float] = (0.0056, -0.00043)
    c_dec: tuple[float, float] = (0.0009, 0.00025)
    met_curve: MetCurve | None = None


#: The paper's coefficients (Boukhalfi et al. 2015): the ``paper-2015`` built-in model.
PAPER_REGRESSION = NhrRegression()
#: The built-in ``default`` model: the paper's rates c_inc and c_dec, and a threshold that is the
#: work needed to hold the current NHR under the Compendium calibration (t_root = 0 + hold(NHR)),
#: so standing stays at rest and steady activities settle at their Compendium %VO2R.
CALIBRATED_REGRESSION = NhrRegression(t_root=(0.0, 0.0), met_curve=MetCurve())


@dataclasses.dataclass(frozen=True)
class NhrParams:
    """Coefficients of the per-second NHR recursion (floats, or arrays of shape (N,)).

    Attributes
    ----------
    t_root : float or ndarray
        Work threshold (W/kg) above which NHR rises.
    c_inc, c_dec : float or ndarray
        Rates of increase and decrease (per W/kg per second).
    reserve_mets : float or ndarray
        VO2 reserve in METs, ``VO2max / 3.5 - 1`` (used with ``met_curve`` only).
    met_curve : MetCurve or None
        None: the paper's constant threshold. Otherwise the threshold adds the work that holds the
        current NHR (Compendium calibration).
    """

    t_root: Any
    c_inc: Any
    c_dec: Any
    reserve_mets: Any = 0.0
    met_curve: MetCurve | None = None

    @classmethod
    def from_training_level(cls, training_level: Any,
                            regression: NhrRegression = PAPER_REGRESSION,
                            vo2max: Any = None) -> NhrParams:
        """Coefficients for a training level (scalar or array) from a TL regression.

        The rates ``c_inc`` and ``c_dec`` are floored at 0 **(choice)**: a regression fitted on a
        lab's training levels can cross zero when extrapolated (a steep negative c_inc slope reaching
        TL 10), and a negative rate would make heart rate fall under effort. At 0 NHR holds instead.
        ``vo2max`` (ml/kg/min) is needed when the regression has a ``met_curve``.
        """
        tl = np.asarray(training_level, dtype=float)
        t_root = regression.t_root[0] + regression.t_root[1] * tl
        rates = [np.maximum(a + b * tl, 0.0) for a, b in (regression.c_inc, regression.c_dec)]
        t, c_inc, c_dec = (float(v) if v.ndim == 0 else v for v in (t_root, *rates))
        if regression.met_curve is None:
            return cls(t, c_inc, c_dec)
        if vo2max is None:
            raise UserError("vo2max: expected the character's VO2max for the Compendium-calibrated "
                            "NHR model, found none")
        reserve = np.asarray(vo2max, dtype=float) / VO2_REST_ML_PER_KG_MIN - 1.0
        return cls(t, c_inc, c_dec, float(reserve) if reserve.ndim == 0 else reserve,
                   regression.met_curve)

    def threshold_w_per_kg(self, nhr: Any) -> Any:
        """The work threshold at this NHR: ``t_root`` (+ the work holding NHR, if calibrated)."""
        if self.met_curve is None:
            return self.t_root
        return self.t_root + self.met_curve.hold_w_per_kg(nhr, self.reserve_mets)


def nhr_step(nhr: Any, w_per_kg: Any, params: NhrParams, dt_s: float = 1.0) -> np.ndarray:
    """One step of the paper's NHR recursion with dt scaling.

    ``dNHR = c_inc (w - t) (1 - NHR)^2`` if ``w > t`` else ``c_dec (w - t) NHR^2``;
    ``NHR <- clip(NHR + dt dNHR, 0, 1)`` (``dt = 1`` is the paper). ``t`` is t_root for the
    paper's model; the calibrated model adds the work that holds the current NHR
    (:meth:`NhrParams.threshold_w_per_kg`), which gives a plateau at the Compendium's %VO2R.

    Parameters
    ----------
    nhr : float or ndarray
        Normalised heart rate before the step.
    w_per_kg : float or ndarray
        Mechanical work over the last second (W/kg).
    params : NhrParams
        Coefficients (broadcast against ``nhr``).
    dt_s : float
        Step length in seconds.

    Returns
    -------
    ndarray
        NHR after the step, in [0, 1].
    """
    nhr = np.asarray(nhr, dtype=float)
    excess = np.asarray(w_per_kg, dtype=float) - params.threshold_w_per_kg(nhr)
    up = params.c_inc * excess * (1.0 - nhr) ** 2
    down = params.c_dec * excess * nhr ** 2
    return np.clip(nhr + dt_s * np.where(excess > 0.0, up, down), 0.0, 1.0)


# --------------------------------------------------------------------------- EPOC

@dataclasses.dataclass(frozen=True)
class EpocParams:
    """The documented EPOC recursion (our choice; Firstbeat's function f is proprietary).

    ``I = VO2 / VO2max``; if ``I > threshold``: ``EPOC += dt k_up (I - threshold)^2``, otherwise
    ``EPOC *= exp(-dt / tau_s)``.

    Values: ``k_up = 0.15`` ml/kg/s makes 30 min at 70 %VO2max accumulate
    ``1800 * 0.15 * 0.35^2 = 33`` ml/kg ("a few tens", the range Firstbeat reports for such a
    session); ``tau_s = 300`` s (5 min) is the fast component of post-exercise oxygen recovery
    (several minutes). ``scale_ml_per_kg = 100`` normalises EPOC for the SVR: 100 ml/kg is about
    what 30 min at VO2max would give (0.15 * 0.65^2 * 1800 = 114), so ``epoc_norm`` stays near
    [0, 1].
    """

    k_up: float = 0.15
    tau_s: float = 300.0
    threshold: float = 0.35
    scale_ml_per_kg: float = 100.0


def epoc_step(epoc: Any, intensity: Any, params: EpocParams, dt_s: float,
              decay: float | None = None) -> np.ndarray:
    """One step of the EPOC recursion (ml/kg); ``decay`` is ``exp(-dt/tau)`` if precomputed."""
    decay = math.exp(-dt_s / params.tau_s) if decay is None else decay
    excess = np.asarray(intensity, dtype=float) - params.threshold
    return np.where(excess > 0.0, epoc + dt_s * params.k_up * excess ** 2, epoc * decay)


# --------------------------------------------------------------------------- per-character parameters

@dataclasses.dataclass(frozen=True)
class PhysiologyParams:
    """Everything the recursion and the derived quantities need (floats or arrays of shape (N,)).

    Build one with :meth:`from_character`, or many with :meth:`stack`.
    """

    hr_rest_bpm: Any
    hr_max_bpm: Any
    vo2max: Any
    rr_max: Any
    nhr: NhrParams
    epoc: EpocParams = EpocParams()
    vo2_rest: float = VO2_REST_ML_PER_KG_MIN
    rr_rest: float = RR_REST_PER_MIN
    update_period_s: float = 1.0

    @classmethod
    def from_character(cls, character: _PersonLike, *, hr_max_formula: str = "tanaka",
                       regression: NhrRegression = PAPER_REGRESSION,
                       nhr: NhrParams | None = None, epoc: EpocParams = EpocParams(),
                       update_period_s: float = 1.0) -> PhysiologyParams:
        """Parameters for one character (age, sex, height_m, mass_kg, training_level, and
        optional measured hr_rest_bpm / hr_max_bpm, which override the charts).

        ``nhr`` gives explicit NHR coefficients (e.g. a participant's fitted ones); otherwise they
        come from ``regression`` at the character's training level.
        """
        c = character
        bounds.check("update_period_s", update_period_s)
        hr_rest = c.hr_rest_bpm if c.hr_rest_bpm is not None else hr_rest_bpm(
            c.age, c.sex, c.training_level)
        hr_max = c.hr_max_bpm if c.hr_max_bpm is not None else hr_max_bpm(c.age, hr_max_formula)
        if hr_max <= hr_rest:
            raise UserError(f"heart rate: expected hr_max_bpm > hr_rest_bpm, found max {hr_max:g} "
                            f"<= rest {hr_rest:g}")
        vo2max = vo2max_ml_per_kg_min(c.age, c.sex, c.height_m, c.mass_kg, c.training_level)
        return cls(hr_rest_bpm=float(hr_rest), hr_max_bpm=float(hr_max), vo2max=vo2max,
                   rr_max=rr_max_per_min(c.training_level),
                   nhr=nhr or NhrParams.from_training_level(c.training_level, regression, vo2max),
                   epoc=epoc, update_period_s=update_period_s)

    @classmethod
    def stack(cls, items: list[PhysiologyParams]) -> PhysiologyParams:
        """Stack single-character parameters into arrays of shape (N,) (shared scalars kept)."""
        first = items[0]

        def arr(get: Any) -> np.ndarray:
            return np.array([get(p) for p in items], dtype=float)

        return dataclasses.replace(
            first, hr_rest_bpm=arr(lambda p: p.hr_rest_bpm), hr_max_bpm=arr(lambda p: p.hr_max_bpm),
            vo2max=arr(lambda p: p.vo2max), rr_max=arr(lambda p: p.rr_max),
            nhr=NhrParams(arr(lambda p: p.nhr.t_root), arr(lambda p: p.nhr.c_inc),
                          arr(lambda p: p.nhr.c_dec), arr(lambda p: p.nhr.reserve_mets),
                          first.nhr.met_curve))


def derived(nhr: Any, epoc: Any, params: PhysiologyParams) -> dict[str, np.ndarray]:
    """HR (bpm), VO2 (ml/kg/min), respiration rate (1/min), EPOC and normalised EPOC from NHR.

    ``HR = HR_rest + NHR (HR_max - HR_rest)``; VO2 and respiration rate are proportional to NHR
    between their rest and max values (Swain & Leutholtz 1997: %HRR = %VO2R).
    """
    nhr = np.asarray(nhr, dtype=float)
    epoc = np.asarray(epoc, dtype=float)
    return {
        "nhr": nhr,
        "hr_bpm": params.hr_rest_bpm + nhr * (params.hr_max_bpm - params.hr_rest_bpm),
        "vo2": params.vo2_rest + nhr * (params.vo2max - params.vo2_rest),
        "resp_rate": params.rr_rest + nhr * (params.rr_max - params.rr_rest),
        "epoc": epoc,
        "epoc_norm": epoc / params.epoc.scale_ml_per_kg,
    }


def _tick(nhr: np.ndarray, epoc: np.ndarray, w_per_kg: Any,
          params: PhysiologyParams) -> tuple[np.ndarray, np.ndarray]:
    """One recursion tick (dt = update period): NHR first, then EPOC from the new VO2."""
    dt = params.update_period_s
    nhr = nhr_step(nhr, w_per_kg, params.nhr, dt)
    intensity = (params.vo2_rest + nhr * (params.vo2max - params.vo2_rest)) / params.vo2max
    decay = math.exp(-dt / params.epoc.tau_s)
    return nhr, epoc_step(epoc, intensity, params.epoc, dt, decay)


# --------------------------------------------------------------------------- the two paths

class PhysiologyState:
    """Streaming physiology for one character or N characters at once.

    Parameters
    ----------
    params : PhysiologyParams
        From :meth:`PhysiologyParams.from_character` (or :meth:`PhysiologyParams.stack`).
    nhr0 : float or ndarray
        Initial NHR (0 = at rest).
    epoc0 : float or ndarray
        Initial EPOC in ml/kg.
    """

    def __init__(self, params: PhysiologyParams, nhr0: Any = 0.0, epoc0: Any = 0.0) -> None:
        shape = np.shape(params.hr_rest_bpm)
        self.params = params
        self.nhr = np.broadcast_to(np.asarray(nhr0, dtype=float), shape).copy()
        self.epoc = np.broadcast_to(np.asarray(epoc0, dtype=float), shape).copy()
        self.elapsed_s = 0.0
        self.ticks = 0

    def step(self, w_per_kg: Any, dt_s: float) -> dict[str, np.ndarray]:
        """Advance by one frame of ``dt_s`` seconds with the current work ``w_per_kg`` (W/kg).

        The recursion runs once for each whole update period completed (possibly zero, possibly
        several if ``dt_s`` is long).

        Returns
        -------
        dict
            ``nhr, hr_bpm, vo2, resp_rate, epoc, epoc_norm`` after this frame.
        """
        self.elapsed_s += float(dt_s)
        target = int(math.floor(self.elapsed_s / self.params.update_period_s))
        while self.ticks < target:
            self.nhr, self.epoc = _tick(self.nhr, self.epoc, w_per_kg, self.params)
            self.ticks += 1
        return derived(self.nhr, self.epoc, self.params)

    def run(self, w_per_kg: Any, dt_s: Any) -> dict[str, np.ndarray]:
        """Advance by T frames at once (one character): :meth:`step` on each, vectorised.

        A clip run in consecutive pieces gives :func:`simulate`'s numbers on the whole clip (the
        clock is the same sequential sum; the recursion runs once per tick in both).

        Parameters
        ----------
        w_per_kg : array_like, shape (T,)
        dt_s : float or array_like, shape (T,)

        Returns
        -------
        dict
            Arrays of shape (T,): ``nhr, hr_bpm, vo2, resp_rate, epoc, epoc_norm``.
        """
        w = np.asarray(w_per_kg, dtype=float)
        dt = np.broadcast_to(np.asarray(dt_s, dtype=float), w.shape)
        elapsed = np.cumsum(np.concatenate([[self.elapsed_s], dt]))[1:]  # continues the sequential sum
        ticks_after = np.floor(elapsed / self.params.update_period_s).astype(np.int64)
        n_ticks = max(int(ticks_after[-1]) - self.ticks, 0) if w.size else 0
        tick_frame = np.searchsorted(ticks_after, np.arange(self.ticks + 1, self.ticks + n_ticks + 1), side="left")
        nhr_t = np.empty(n_ticks + 1)
        epoc_t = np.empty(n_ticks + 1)
        nhr_t[0], epoc_t[0] = self.nhr, self.epoc
        nhr, epoc = self.nhr, self.epoc
        for k, frame in enumerate(tick_frame, start=1):
            nhr, epoc = _tick(nhr, epoc, w[frame], self.params)
            nhr_t[k], epoc_t[k] = nhr, epoc
        self.nhr, self.epoc = np.asarray(nhr, dtype=float), np.asarray(epoc, dtype=float)
        if w.size:
            self.elapsed_s = float(elapsed[-1])
            at = ticks_after - self.ticks
            self.ticks += n_ticks
        else:
            at = ticks_after
        return derived(nhr_t[at], epoc_t[at], self.params)


def simulate(w_per_kg: Any, dt_s: Any, character: _PersonLike | PhysiologyParams, *,
             nhr0: float = 0.0, epoc0: float = 0.0) -> dict[str, np.ndarray]:
    """Whole-clip physiology: the same curves as stepping :class:`PhysiologyState` frame by frame.

    Parameters
    ----------
    w_per_kg : array_like, shape (T,)
        Work per frame (W/kg over the last second).
    dt_s : float or array_like, shape (T,)
        Frame interval in seconds, or one interval per frame (a game loop's jittery dt); frame k
        advances the clock by ``dt_s[k]``.
    character : character-like or PhysiologyParams
        A character (see :meth:`PhysiologyParams.from_character`) or ready parameters.
    nhr0, epoc0 : float
        Initial state.

    Returns
    -------
    dict
        Arrays of shape (T,): ``nhr, hr_bpm, vo2, resp_rate, epoc, epoc_norm``.
    """
    params = character if isinstance(character, PhysiologyParams) else \
        PhysiologyParams.from_character(character)
    return PhysiologyState(params, float(nhr0), float(epoc0)).run(w_per_kg, dt_s)


def nhr_from_hr_bpm(hr_bpm: Any, hr_rest: Any, hr_max: Any) -> np.ndarray:
    """Normalised heart rate ``(HR - HR_rest) / (HR_max - HR_rest)`` clipped to [0, 1]."""
    hr = np.asarray(hr_bpm, dtype=float)
    return np.clip((hr - hr_rest) / (np.asarray(hr_max, dtype=float) - hr_rest), 0.0, 1.0)
