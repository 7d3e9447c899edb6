"""Fitting the paper's heart-rate model (SCIENCE.md section 3) and evaluating it like the paper.

Per participant, a two-leaf regression tree predicts the per-second change of the normalised heart
rate, dNHR, from (w, NHR). Its root test ``w > t`` splits rises from falls, and inside each leaf the
coefficient c is fitted by least squares of the paper's leaf models::

    dNHR = c_inc (w - t) (1 - NHR)^2     upper leaf (w > t)
    dNHR = c_dec (w - t) NHR^2           lower leaf (w <= t)

**Split search (choice).** The threshold is found by an exhaustive search, not by scikit-learn's
``DecisionTreeRegressor(max_depth=1)``: a plain tree scores a split by the variance around a constant
per leaf and can only place ``t`` half-way between two observed values of w, whereas the paper's
leaves are the linear-in-c models above, in which ``t`` also enters the prediction. So every candidate
``t`` (all mid-points between distinct w, plus a fine grid across the range of w, which matters when
work comes in a few constant levels) is scored by the residual sum of squares of the two leaf models,
each c in closed form from prefix sums: the whole search is O(n log n). Candidates whose leaves get
negative coefficients (a rise below threshold, a fall above it) are rejected.

**Derivative (choice).** dNHR is a centred difference over ``smooth_s`` seconds of the measured NHR
(default 3 s), because strap HR at 1 Hz carries about +-2 bpm of beat-to-beat noise.

Then t, c_inc and c_dec are regressed linearly on training level (the global model), and the models
are scored by *simulating* the recursion over whole sessions from the first measured value (the
prediction feeds the next step), always on data they were not fitted on, except the labelled
in-sample score (see :data:`MODELS`): the per-participant tree on held-out time (another session),
one threshold tree pooled over everyone else without training level (ours: not the paper's pooled
model, which was an unpruned regression tree), and the training-level regression on held-out
participants (leave one participant out).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from effortface.core.errors import UserError
from effortface.synth.physiology import NhrParams, NhrRegression, nhr_step

#: default centred-difference span for dNHR, seconds (choice, see module docstring)
DEFAULT_SMOOTH_S = 3
#: minimal share of the samples in each leaf of the threshold tree
MIN_LEAF_FRACTION = 0.05
#: number of evenly spaced candidate thresholds added to the mid-points
N_GRID_THRESHOLDS = 400


@dataclasses.dataclass(frozen=True)
class HrSeries:
    """One session of per-second data for the heart-rate model.

    Parameters
    ----------
    participant, session : str
        Participant code and session id.
    training_level : float
        The participant's training level (0 ... 10).
    t_s : ndarray
        Seconds since session start, one per second (gaps allowed).
    w_per_kg : ndarray
        Mechanical work over the last second, W/kg.
    nhr : ndarray
        Measured normalised heart rate in [0, 1]; NaN where the strap gave no valid value.
    hr_rest_bpm, hr_max_bpm : float
        The rest and max used to normalise (to express errors in bpm).
    """

    participant: str
    session: str
    training_level: float
    t_s: np.ndarray
    w_per_kg: np.ndarray
    nhr: np.ndarray
    hr_rest_bpm: float
    hr_max_bpm: float


@dataclasses.dataclass(frozen=True)
class HrCoefficients:
    """One heart-rate model: threshold ``t_root_w_per_kg`` and leaf factors (per second)."""

    t_root_w_per_kg: float
    c_inc: float
    c_dec: float

    def as_dict(self) -> dict[str, float]:
        """JSON-ready dictionary."""
        return dataclasses.asdict(self)

    @classmethod
    def from_nhr_params(cls, params: NhrParams) -> HrCoefficients:
        """The same model from the runtime's scalar :class:`~effortface.synth.physiology.NhrParams`."""
        return cls(float(params.t_root), float(params.c_inc), float(params.c_dec))

    def to_nhr_params(self) -> NhrParams:
        """The same model as the runtime's :class:`~effortface.synth.physiology.NhrParams`."""
        return NhrParams(self.t_root_w_per_kg, self.c_inc, self.c_dec)


@dataclasses.dataclass(frozen=True)
class LinearFit:
    """``value = intercept + slope * training_level`` (with the fit's r)."""

    intercept: float
    slope: float
    r: float

    def at(self, training_level: float) -> float:
        """Value at ``training_level``."""
        return self.intercept + self.slope * training_level


@dataclasses.dataclass(frozen=True)
class TlRegression:
    """The global model: t_root, c_inc and c_dec as linear functions of training level."""

    t_root: LinearFit
    c_inc: LinearFit
    c_dec: LinearFit

    def at(self, training_level: float) -> HrCoefficients:
        """Coefficients for a character of ``training_level`` (factors floored at 0, as the runtime)."""
        return HrCoefficients.from_nhr_params(
            NhrParams.from_training_level(training_level, self.to_nhr_regression()))

    def to_nhr_regression(self) -> NhrRegression:
        """The runtime's :class:`~effortface.synth.physiology.NhrRegression` ``(intercept, slope)`` pairs."""
        t, c_inc, c_dec = ((f.intercept, f.slope) for f in (self.t_root, self.c_inc, self.c_dec))
        return NhrRegression(t, c_inc, c_dec)

    def as_dict(self) -> dict[str, dict[str, float]]:
        """JSON-ready dictionary ``{name: {intercept, slope, r}}``."""
        return {k: dataclasses.asdict(getattr(self, k)) for k in ("t_root", "c_inc", "c_dec")}


# --------------------------------------------------------------------------- samples


def step_samples(series: HrSeries, smooth_s: int = DEFAULT_SMOOTH_S
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Training samples (w, NHR, dNHR per second) from one session.

    Parameters
    ----------
    series : HrSeries
        One session.
    smooth_s : int
        Span of the centred difference, seconds (1 = plain forward difference).

    Returns
    -------
    w_per_kg, nhr, dnhr_per_s : ndarray
        Samples where the whole span is measured and evenly spaced at 1 s.
    """
    t, w, nhr = (np.asarray(a, dtype=float) for a in (series.t_s, series.w_per_kg, series.nhr))
    k = max(int(smooth_s), 1)
    lo, hi = k // 2, k - k // 2
    if len(t) <= k:
        return np.empty(0), np.empty(0), np.empty(0)
    centre = np.arange(lo, len(t) - hi)
    dnhr = (nhr[centre + hi] - nhr[centre - lo]) / (t[centre + hi] - t[centre - lo])
    level = _centred_mean(nhr, k)[centre]
    even = np.isclose(t[centre + hi] - t[centre - lo], k)
    ok = even & np.isfinite(dnhr) & np.isfinite(level) & np.isfinite(w[centre])
    return w[centre][ok], level[ok], dnhr[ok]


def _centred_mean(x: np.ndarray, k: int) -> np.ndarray:
    """Moving mean over k + 1 samples centred like the difference (NaN-propagating)."""
    lo, hi = k // 2, k - k // 2
    padded = np.concatenate([np.full(lo, np.nan), x, np.full(hi, np.nan)])
    windows = np.lib.stride_tricks.sliding_window_view(padded, k + 1)
    return windows.mean(axis=1)


def _pool_samples(series: Sequence[HrSeries], smooth_s: int
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Concatenated step samples of several sessions."""
    parts = [step_samples(s, smooth_s) for s in series]
    return tuple(np.concatenate([p[i] for p in parts]) if parts else np.empty(0)
                 for i in range(3))  # type: ignore[return-value]  # three arrays


# --------------------------------------------------------------------------- the tree


def fit_threshold_tree(w_per_kg: np.ndarray, nhr: np.ndarray, dnhr_per_s: np.ndarray,
                       min_leaf_fraction: float = MIN_LEAF_FRACTION) -> HrCoefficients:
    """Fit the two-leaf tree ``w > t`` with the paper's leaf models (exhaustive split search).

    Parameters
    ----------
    w_per_kg, nhr, dnhr_per_s : ndarray
        Samples from :func:`step_samples`.
    min_leaf_fraction : float
        Each leaf must hold at least this share of the samples.

    Returns
    -------
    HrCoefficients

    Raises
    ------
    ValueError
        If there are too few samples or no spread in w to place a threshold.
    """
    w, nhr, y = (np.asarray(a, dtype=float) for a in (w_per_kg, nhr, dnhr_per_s))
    _check_spread(len(w), len(w) >= 10 and not np.ptp(w) <= 0)
    m = _sorted_moments(w, nhr, y)
    t_cand = _candidate_thresholds(m.w_per_kg)
    n_low = np.searchsorted(m.w_per_kg, t_cand, side="right")  # samples with w <= t
    return _best_split(t_cand, n_low, len(w), m.low[:, n_low], m.up[:, len(w) - n_low], min_leaf_fraction)


def _check_spread(n: int, spread: bool) -> None:
    """The tree's input check: at least 10 samples and some spread in w."""
    if n < 10 or not spread:
        raise ValueError(f"heart-rate fit: expected >= 10 samples (evenly spaced seconds t_s with "
                         f"hr_bpm) with varying work (w_per_kg), found {n}"
                         + (" with constant work" if n >= 10 else ""))


@dataclasses.dataclass(frozen=True)
class _SortedMoments:
    """Samples sorted by work with the prefix sums of both leaves (see :func:`_leaf_moments`).

    ``low[:, k]``: moments of the k smallest w (lower leaf, g = NHR^2); ``up[:, k]``: moments of the
    k largest w (upper leaf, g = (1 - NHR)^2).
    """

    w_per_kg: np.ndarray
    low: np.ndarray
    up: np.ndarray


def _sorted_moments(w: np.ndarray, nhr: np.ndarray, y: np.ndarray) -> _SortedMoments:
    """Sort the samples by w (stable) and take both leaves' prefix sums."""
    order = np.argsort(w, kind="stable")
    w, nhr, y = w[order], nhr[order], y[order]
    return _SortedMoments(w, _leaf_moments(w, nhr**2, y),
                          _leaf_moments(w[::-1], ((1 - nhr) ** 2)[::-1], y[::-1]))


def _best_split(t_cand: np.ndarray, n_low: np.ndarray, n: int, low: np.ndarray, up: np.ndarray,
                min_leaf_fraction: float) -> HrCoefficients:
    """The candidate of least residual sum of squares (leaf moments ``low``, ``up`` per candidate)."""
    sse_l, c_l = _leaf_sse(low, t_cand)
    sse_u, c_u = _leaf_sse(up, t_cand)
    min_n = max(int(min_leaf_fraction * n), 3)
    ok = (n_low >= min_n) & (n - n_low >= min_n)
    score = np.where(ok & (c_l >= 0) & (c_u >= 0), sse_l + sse_u, np.inf)
    if not np.isfinite(score).any():
        score = np.where(ok, sse_l + sse_u, np.inf)
    if not np.isfinite(score).any():
        raise ValueError("heart-rate fit: expected work on both sides of a threshold, found none")
    best = int(np.argmin(score))
    return HrCoefficients(float(t_cand[best]), float(c_u[best]), float(c_l[best]))


def _candidate_thresholds(w_sorted: np.ndarray) -> np.ndarray:
    """Mid-points between distinct values of w plus an even grid over its range."""
    return _candidates_from_values(np.unique(w_sorted))


def _candidates_from_values(u: np.ndarray) -> np.ndarray:
    """:func:`_candidate_thresholds` from the sorted distinct values ``u`` of w."""
    mids = (u[:-1] + u[1:]) / 2
    grid = np.linspace(u[0], u[-1], N_GRID_THRESHOLDS)
    return np.unique(np.concatenate([mids, grid]))


def _merged_candidates(u: np.ndarray) -> np.ndarray:
    """:func:`_candidates_from_values` (the same array) by merging the two sorted parts, no sort."""
    mids = (u[:-1] + u[1:]) / 2
    grid = np.linspace(u[0], u[-1], N_GRID_THRESHOLDS)
    merged = np.insert(mids, np.searchsorted(mids, grid), grid)
    keep = np.ones(len(merged), dtype=bool)
    keep[1:] = merged[1:] != merged[:-1]
    return merged[keep]


def _leaf_moments(w: np.ndarray, g: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Prefix sums [S(w g y), S(g y), S(w^2 g^2), S(w g^2), S(g^2), S(y^2)], row 0 = empty."""
    terms = np.stack([w * g * y, g * y, w * w * g * g, w * g * g, g * g, y * y])
    return np.concatenate([np.zeros((6, 1)), np.cumsum(terms, axis=1)], axis=1)


def _leaf_sse(moments: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Residual sum of squares and LS coefficient of ``y = c (w - t) g`` from a leaf's moments
    (one column per candidate t)."""
    s_wgy, s_gy, s_wwgg, s_wgg, s_gg, s_yy = moments
    sxy = s_wgy - t * s_gy
    sxx = s_wwgg - 2 * t * s_wgg + t * t * s_gg
    with np.errstate(divide="ignore", invalid="ignore"):
        c = np.where(sxx > 1e-12, sxy / sxx, 0.0)
        sse = np.where(sxx > 1e-12, s_yy - sxy * sxy / sxx, s_yy)
    return sse, c


def pooled_trees_leaving_each_out(samples: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]],
                                  min_leaf_fraction: float = MIN_LEAF_FRACTION
                                  ) -> dict[str, HrCoefficients]:
    """The pooled threshold tree fitted without each participant in turn, from shared prefix sums.

    Equal (up to the order of floating-point additions) to :func:`fit_threshold_tree` on the other
    participants' samples concatenated, but each held-out fit costs O(own samples + candidate
    thresholds) instead of a sort of everyone's samples: the samples are sorted and the leaves'
    prefix sums taken once over everyone, and at every candidate threshold the held-out
    participant's own counts and sums (from their own sorted prefix sums) are subtracted. The
    candidates are those of the refit exactly: the mid-points between the work values that remain
    (a value is dropped when only the held-out participant has it) plus the even grid over their
    range.

    Parameters
    ----------
    samples : dict
        Participant code -> (w_per_kg, nhr, dnhr_per_s), their sessions' step samples
        (:func:`step_samples`) concatenated.
    min_leaf_fraction : float
        As in :func:`fit_threshold_tree` (a share of the remaining samples).

    Returns
    -------
    dict
        Participant code -> the pooled tree fitted on everyone else.

    Raises
    ------
    ValueError
        As :func:`fit_threshold_tree` on the remaining samples.
    """
    arrays = [[np.asarray(own[k], dtype=float) for own in samples.values()] for k in range(3)]
    whole = _sorted_moments(*(np.concatenate(a) if a else np.empty(0) for a in arrays))
    values, counts = np.unique(whole.w_per_kg, return_counts=True)
    out = {}
    for code, own in samples.items():
        mine = _sorted_moments(*(np.asarray(a, dtype=float) for a in own))
        out[code] = _tree_without(whole, values, counts, mine, min_leaf_fraction)
    return out


def _tree_without(whole: _SortedMoments, values: np.ndarray, counts: np.ndarray, mine: _SortedMoments,
                  min_leaf_fraction: float) -> HrCoefficients:
    """The threshold tree on ``whole`` minus ``mine`` (``values``/``counts``: whole's distinct w)."""
    n_all, n_mine = len(whole.w_per_kg), len(mine.w_per_kg)
    n = n_all - n_mine
    own_values, own_counts = np.unique(mine.w_per_kg, return_counts=True)
    at = np.searchsorted(values, own_values)
    present = np.ones(len(values), dtype=bool)
    present[at[counts[at] == own_counts]] = False  # values only the held-out participant has
    u = values[present]
    _check_spread(n, len(u) >= 2)
    t_cand = _merged_candidates(u)
    below_all = np.searchsorted(whole.w_per_kg, t_cand, side="right")
    below_mine = np.searchsorted(mine.w_per_kg, t_cand, side="right")
    low = whole.low[:, below_all] - mine.low[:, below_mine]
    up = whole.up[:, n_all - below_all] - mine.up[:, n_mine - below_mine]
    return _best_split(t_cand, below_all - below_mine, n, low, up, min_leaf_fraction)


# --------------------------------------------------------------------------- fits


#: participants needed to train: the TL model is scored leaving one participant out, and the
#: remaining ones must still span two training levels
MIN_PARTICIPANTS = 3


def check_hr_series(series: Sequence[HrSeries], source: str = "table",
                    smooth_s: int = DEFAULT_SMOOTH_S) -> None:
    """Refuse data the heart-rate models cannot be fitted and scored on, before any work starts.

    Parameters
    ----------
    series : sequence of HrSeries
        The sessions (from :func:`effortface.train.dataset.hr_series`).
    source : str
        The table or sessions, for the message.
    smooth_s : int
        Span of the centred difference, seconds.

    Raises
    ------
    UserError
        Naming ``source`` (and the participant) when there are fewer than :data:`MIN_PARTICIPANTS`
        participants, when leaving one out leaves a single training level, or when a participant's
        own tree cannot be fitted.
    """
    groups = by_participant(series)
    tls = {code: float(ss[0].training_level) for code, ss in groups.items()}
    need = (f"{source}: expected sessions of at least {MIN_PARTICIPANTS} participants with 2 or more "
            "distinct training levels (without any one of them) to fit the TL model, found")
    if len(groups) < MIN_PARTICIPANTS:
        raise UserError(f"{need} {len(groups)} participant{'s' * (len(groups) != 1)}")
    for code in groups:
        rest = {tl for c, tl in tls.items() if c != code}
        if len(rest) < 2:
            raise UserError(f"{need} only training level {rest.pop():g} without {code}")
    for code, own in groups.items():
        try:
            fit_participant(own, smooth_s)
        except ValueError as exc:
            raise UserError(f"{source}: participant {code}: {exc}") from None


def fit_participant(series: Sequence[HrSeries], smooth_s: int = DEFAULT_SMOOTH_S) -> HrCoefficients:
    """Fit one participant's tree on all their sessions (see :func:`fit_threshold_tree`)."""
    return fit_threshold_tree(*_pool_samples(series, smooth_s))


def fit_pooled(series: Sequence[HrSeries], smooth_s: int = DEFAULT_SMOOTH_S) -> HrCoefficients:
    """Fit one tree to everyone's samples pooled, ignoring training level (the paper's 2nd model)."""
    return fit_threshold_tree(*_pool_samples(series, smooth_s))


def by_participant(series: Sequence[HrSeries]) -> dict[str, list[HrSeries]]:
    """Group sessions by participant code (in first-seen order)."""
    groups: dict[str, list[HrSeries]] = {}
    for s in series:
        groups.setdefault(s.participant, []).append(s)
    return groups


def fit_tl_regression(training_levels: Sequence[float], fits: Sequence[HrCoefficients]) -> TlRegression:
    """Regress t_root, c_inc and c_dec linearly on training level (the paper's global model).

    Parameters
    ----------
    training_levels : sequence of float
        One per participant.
    fits : sequence of HrCoefficients
        The participants' own fits, same order.

    Returns
    -------
    TlRegression

    Raises
    ------
    ValueError
        If fewer than two distinct training levels are given.
    """
    tl = np.asarray(training_levels, dtype=float)
    if len(np.unique(tl)) < 2:
        raise ValueError(f"training-level regression: expected >= 2 distinct levels, found {sorted(set(tl))}")
    return TlRegression(*(_linear(tl, np.array([getattr(f, k) for f in fits]))
                          for k in ("t_root_w_per_kg", "c_inc", "c_dec")))


def _linear(x: np.ndarray, y: np.ndarray) -> LinearFit:
    """Least-squares line with its correlation."""
    slope, intercept = np.polyfit(x, y, 1)
    r = float(np.corrcoef(x, y)[0, 1]) if np.std(y) > 0 else 0.0
    return LinearFit(float(intercept), float(slope), r)


@dataclasses.dataclass(frozen=True)
class HrModelFit:
    """Everything fitted on a training set: per-participant trees, the pooled tree, the TL model."""

    per_participant: dict[str, HrCoefficients]
    training_levels: dict[str, float]
    pooled: HrCoefficients
    tl_regression: TlRegression


def fit_hr_model(series: Sequence[HrSeries], smooth_s: int = DEFAULT_SMOOTH_S) -> HrModelFit:
    """Fit the paper's heart-rate models on ``series`` (all participants).

    Parameters
    ----------
    series : sequence of HrSeries
        Sessions of at least two participants of different training levels.
    smooth_s : int
        Span of the centred difference for dNHR, seconds.

    Returns
    -------
    HrModelFit
    """
    groups = by_participant(series)
    per = {code: fit_participant(ss, smooth_s) for code, ss in groups.items()}
    tls = {code: float(ss[0].training_level) for code, ss in groups.items()}
    tl_reg = fit_tl_regression([tls[c] for c in per], list(per.values()))
    return HrModelFit(per, tls, fit_pooled(series, smooth_s), tl_reg)


# --------------------------------------------------------------------------- simulation


def simulate_nhr(w_per_kg: np.ndarray, nhr0: float, coef: HrCoefficients, dt_s: float = 1.0) -> np.ndarray:
    """Run the recursion over a work series from ``nhr0`` (the prediction feeds the next step).

    Parameters
    ----------
    w_per_kg : ndarray
        Work per step, W/kg (NaN treated as 0: no work recorded).
    nhr0 : float
        NHR at the first step.
    coef : HrCoefficients
        The model.
    dt_s : float
        Step, seconds.

    Returns
    -------
    ndarray
        NHR at every step (element 0 is ``nhr0``).
    """
    w = np.nan_to_num(np.asarray(w_per_kg, dtype=float))
    params = coef.to_nhr_params()
    out = np.empty(len(w))
    nhr = np.asarray(float(np.clip(nhr0, 0.0, 1.0)))
    for i, wi in enumerate(w):
        out[i] = nhr
        nhr = nhr_step(nhr, wi, params, dt_s)
    return out


def simulate_series(series: HrSeries, coef: HrCoefficients) -> np.ndarray:
    """Simulate one session from its first measured NHR.

    The recursion runs on a 1 s grid from that sample to the end (across a gap in the table the
    last known work is held), and is read back at the session's own ``t_s``.
    """
    i0, w_per_kg, nhr0 = _work_grid(series)
    return _read_back(series, i0, simulate_nhr(w_per_kg, nhr0, coef))


#: most values (steps x sessions) simulated together by :func:`simulate_many`
SIMULATE_BATCH_VALUES = 2_000_000


def simulate_many(jobs: Sequence[tuple[HrSeries, HrCoefficients]]) -> list[np.ndarray]:
    """:func:`simulate_series` for many (session, model) pairs at once, the same numbers.

    The recursion steps every session together (one vectorised step per second instead of one
    Python step per second and session), in batches of sessions of similar length holding at most
    :data:`SIMULATE_BATCH_VALUES` values. Each session runs on its own 1 s grid from its first
    measured NHR, exactly as :func:`simulate_series`; the padding after a shorter session's end is
    discarded.

    Parameters
    ----------
    jobs : sequence of (HrSeries, HrCoefficients)
        Sessions and the model to simulate each with.

    Returns
    -------
    list of ndarray
        Simulated NHR at each session's own ``t_s`` (NaN before its first measured value), in
        ``jobs`` order.

    Raises
    ------
    ValueError
        If a session has no measured heart rate.
    """
    grids = [_work_grid(s) for s, _ in jobs]
    order = sorted(range(len(jobs)), key=lambda j: len(grids[j][1]))
    sims: list[np.ndarray] = [np.empty(0)] * len(jobs)
    start = 0
    while start < len(order):
        stop = start + 1
        while stop < len(order) and (stop + 1 - start) * len(grids[order[stop]][1]) <= SIMULATE_BATCH_VALUES:
            stop += 1
        batch = order[start:stop]
        w = np.zeros((len(grids[batch[-1]][1]), len(batch)))
        for col, j in enumerate(batch):
            w[:len(grids[j][1]), col] = grids[j][1]
        nhr0 = np.array([grids[j][2] for j in batch])
        coefs = [jobs[j][1] for j in batch]
        params = NhrParams(np.array([c.t_root_w_per_kg for c in coefs]), np.array([c.c_inc for c in coefs]),
                           np.array([c.c_dec for c in coefs]))
        out = _simulate_columns(w, nhr0, params)
        for col, j in enumerate(batch):
            sims[j] = out[:len(grids[j][1]), col]
        start = stop
    return [_read_back(s, grids[j][0], sims[j]) for j, (s, _) in enumerate(jobs)]


def _work_grid(series: HrSeries) -> tuple[int, np.ndarray, float]:
    """(first measured index, work on the 1 s grid from there with gaps held, NHR there)."""
    valid = np.flatnonzero(np.isfinite(series.nhr))
    if len(valid) == 0:
        raise ValueError(f"session {series.session}: no measured heart rate to start from")
    i0 = int(valid[0])
    t = np.asarray(series.t_s[i0:], dtype=float)
    grid = t[0] + np.arange(int(round(t[-1] - t[0])) + 1)
    held = np.clip(np.searchsorted(t, grid + 1e-9, side="right") - 1, 0, len(t) - 1)
    w = np.nan_to_num(np.asarray(series.w_per_kg[i0:], dtype=float)[held])
    return i0, w, float(series.nhr[i0])


def _simulate_columns(w_per_kg: np.ndarray, nhr0: np.ndarray, params: NhrParams) -> np.ndarray:
    """The recursion of :func:`simulate_nhr` for every column of ``w_per_kg`` (steps x sessions)."""
    out = np.empty_like(w_per_kg)
    nhr = np.clip(nhr0, 0.0, 1.0)
    for i, wi in enumerate(w_per_kg):
        out[i] = nhr
        nhr = nhr_step(nhr, wi, params, 1.0)
    return out


def _read_back(series: HrSeries, i0: int, sim: np.ndarray) -> np.ndarray:
    """A simulated 1 s grid read back at the session's own ``t_s`` (NaN before ``i0``)."""
    t = np.asarray(series.t_s[i0:], dtype=float)
    pred = np.full(len(series.t_s), np.nan)
    pred[i0:] = sim[np.clip(np.round(t - t[0]).astype(int), 0, len(sim) - 1)]
    return pred


# --------------------------------------------------------------------------- evaluation


@dataclasses.dataclass(frozen=True)
class HrScore:
    """Scores of one simulated session against the measured NHR."""

    participant: str
    session: str
    model: str
    r: float
    rmse_pct: float
    hr_rmse_bpm: float
    n: int


@dataclasses.dataclass
class HrEvaluation:
    """The paper's three models scored per session, with the simulated curves (for Fig. 2)."""

    scores: list[HrScore]
    predictions: dict[tuple[str, str], np.ndarray]  # (model, session) -> simulated NHR
    fit: HrModelFit

    def summary(self) -> dict[str, dict[str, float]]:
        """Mean r, RMSE (% of the NHR range) and HR RMSE (bpm) per model."""
        out: dict[str, dict[str, float]] = {}
        for model in MODELS:
            rows = [s for s in self.scores if s.model == model]
            if rows:
                out[model] = {"r": float(np.nanmean([s.r for s in rows])),
                              "rmse_pct": float(np.mean([s.rmse_pct for s in rows])),
                              "hr_rmse_bpm": float(np.mean([s.hr_rmse_bpm for s in rows])),
                              "n_sessions": len(rows)}
        return out


#: The scored models. ``per_participant``: the participant's own tree fitted on their other
#: sessions (or the other half of a single session) and scored on held-out time;
#: ``per_participant_in_sample``: the same tree fitted on all their sessions and scored on them (the
#: paper's Fig. 2a protocol); ``pooled_threshold``: one two-leaf threshold tree fitted on everyone
#: else pooled, without training level (NOT the paper's pooled model, an unpruned regression tree);
#: ``tl_regression``: the training-level regression fitted without the scored participant.
MODELS = ("per_participant", "per_participant_in_sample", "pooled_threshold", "tl_regression")
#: Which models are scored on data they were not fitted on.
HELD_OUT_MODELS = ("per_participant", "pooled_threshold", "tl_regression")
#: The paper's figures (Boukhalfi et al. 2015), beside ours in the report and the Train stage. Its
#: per-participant figure is in-sample; its pooled figure is for its own (unpruned-tree) pooled model.
PAPER_HR = {"per_participant_in_sample": {"r": 0.88, "rmse_pct": 19.0},
            "pooled_threshold": {"r": 0.21, "rmse_pct": 79.0},
            "tl_regression": {"r": 0.87, "rmse_pct": 24.0}}


def score_series(series: HrSeries, pred: np.ndarray, model: str) -> HrScore:
    """r and RMSE of a simulated session (RMSE in % of the NHR range [0, 1] and in bpm)."""
    ok = np.isfinite(series.nhr) & np.isfinite(pred)
    real, p = series.nhr[ok], pred[ok]
    r = float(np.corrcoef(real, p)[0, 1]) if np.std(real) > 0 and np.std(p) > 0 else float("nan")
    rmse = float(np.sqrt(np.mean((real - p) ** 2)))
    span = series.hr_max_bpm - series.hr_rest_bpm
    return HrScore(series.participant, series.session, model, r, 100 * rmse, rmse * span, int(ok.sum()))


def held_out_time_blocks(own: Sequence[HrSeries]) -> list[tuple[list[HrSeries], list[HrSeries]]]:
    """(fit on, score on) pairs of one participant's sessions: leave one session out, or, with a
    single session, its two halves in time (each scored with a tree fitted on the other)."""
    if len(own) >= 2:
        return [([o for o in own if o is not s], [s]) for s in own]
    s = own[0]
    half = len(s.t_s) // 2
    parts = [dataclasses.replace(s, t_s=s.t_s[sl], w_per_kg=s.w_per_kg[sl], nhr=s.nhr[sl])
             for sl in (slice(None, half), slice(half, None))]
    return [([parts[1]], [parts[0]]), ([parts[0]], [parts[1]])]


def _held_out_time(own: Sequence[HrSeries], smooth_s: int
                   ) -> list[tuple[HrSeries, HrCoefficients | None]]:
    """Each held-out block with the participant's tree fitted on the rest (None if it cannot be)."""
    out: list[tuple[HrSeries, HrCoefficients | None]] = []
    for fit_on, score_on in held_out_time_blocks(own):
        try:
            coef: HrCoefficients | None = fit_participant(fit_on, smooth_s)
        except ValueError:  # e.g. the other session never crossed a threshold: no score
            coef = None
        out.extend((s, coef) for s in score_on)
    return out


def evaluate_hr_models(series: Sequence[HrSeries], smooth_s: int = DEFAULT_SMOOTH_S) -> HrEvaluation:
    """Score the heart-rate models by simulating whole sessions (see :data:`MODELS`).

    ``per_participant`` is fitted on the participant's other sessions (or the other half of a
    single session) and scored on the held-out one; ``per_participant_in_sample`` is fitted and
    scored on all the participant's sessions (paper Fig. 2a); the pooled threshold tree and the
    training-level model are fitted without the scored participant (leave one participant out).

    Parameters
    ----------
    series : sequence of HrSeries
        Sessions of at least three participants (two must remain, of different levels, per fold).
    smooth_s : int
        Span of the centred difference for dNHR, seconds.

    Returns
    -------
    HrEvaluation
        A held-out block that cannot be fitted (too little work variation in the other sessions) is
        not scored; ``summary()``'s ``n_sessions`` counts the scored ones.
    """
    fit = fit_hr_model(series, smooth_s)
    groups = by_participant(series)
    population = _population_models_without(fit, groups, smooth_s)
    jobs: list[tuple[str, HrSeries, HrCoefficients, str]] = []  # (model, scored series, fit, key)
    for code, own in groups.items():
        pooled, tl_regression = population[code]
        for s in own:
            jobs += [("per_participant_in_sample", s, fit.per_participant[code], s.session),
                     ("pooled_threshold", s, pooled, s.session),
                     ("tl_regression", s, tl_regression.at(own[0].training_level), s.session)]
        jobs += [("per_participant", block, coef, f"{block.session}@{block.t_s[0]:g}")
                 for block, coef in _held_out_time(own, smooth_s) if coef is not None]
    simulated = iter(simulate_many([(s, coef) for _, s, coef, _ in jobs]))
    scores, preds = [], {}
    for code, own in groups.items():
        for name, s, _, key in (j for j in jobs if j[1].participant == code):
            preds[(name, key)] = pred = next(simulated)
            scores.append(score_series(s, pred, name))
        for s in own:  # whole-session curve for Fig. 2 (halves joined for a single session)
            preds[("per_participant", s.session)] = _joined(preds, s)
    return HrEvaluation(scores, preds, fit)


def _population_models_without(fit: HrModelFit, groups: dict[str, list[HrSeries]], smooth_s: int
                               ) -> dict[str, tuple[HrCoefficients, TlRegression]]:
    """Per participant, the pooled tree and the training-level regression fitted without them.

    Both are the models ``fit_hr_model`` gives on the other participants' sessions. Refitting them
    once per participant made the evaluation grow as the square of the lab; here the other
    participants' own trees (``fit.per_participant``) are reused for the regression (P lines of P
    points), and the pooled trees come from one sort of everyone's samples
    (:func:`pooled_trees_leaving_each_out`).
    """
    samples = {code: _pool_samples(own, smooth_s) for code, own in groups.items()}
    pooled = pooled_trees_leaving_each_out(samples)
    out = {}
    for code in groups:
        others = [c for c in fit.per_participant if c != code]
        out[code] = (pooled[code], fit_tl_regression([fit.training_levels[c] for c in others],
                                                     [fit.per_participant[c] for c in others]))
    return out


def _joined(preds: dict[tuple[str, str], np.ndarray], s: HrSeries) -> np.ndarray:
    """The held-out per-participant curve of a whole session (NaN where no block was scored)."""
    keys = sorted((k for m, k in preds if m == "per_participant" and k.startswith(f"{s.session}@")),
                  key=lambda k: float(k.rsplit("@", 1)[1]))
    if len(keys) == 1:
        return preds[("per_participant", keys[0])]
    return np.concatenate([preds[("per_participant", k)] for k in keys]) if keys \
        else np.full(len(s.t_s), np.nan)
