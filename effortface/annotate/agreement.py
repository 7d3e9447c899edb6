"""The reliability report: how well raters agree on the blind pose ratings (pure Python + numpy).

Statistics, each per blendshape (poses x raters) and overall (pose-blendshape items x raters):

- **mean absolute disagreement** in % of the weight range [0, 1] (the paper's 11 % figure), per pose,
  per blendshape and overall: :func:`effortface.annotate.reliability.mean_abs_disagreement_pct`;
- **ICC(A,1)** (absolute agreement) and **ICC(C,1)** (consistency), single rater, two-way model,
  McGraw & Wong 1996 (Shrout & Fleiss 1979 ICC(2,1) and ICC(3,1)), from the ANOVA mean squares,
  each with its 95 % confidence interval from the F distribution (McGraw & Wong 1996, Table 7;
  for ICC(A,1) the Satterthwaite degrees of freedom v of Shrout & Fleiss 1979): with the paper's
  18 poses the intervals are wide;
- **Krippendorff's alpha**, interval metric, from the ``krippendorff`` package (missing ratings allowed);
- **Bland-Altman** per rater pair over all items: bias (mean of a - b) and 95 % limits of agreement
  (bias +- 1.96 sd of the differences).

**Confidence intervals that respect the design.** A pose is rated on every blendshape at once, so
the pose x blendshape items of the overall ("all") row are not independent: the F-based intervals,
which assume they are, were too narrow there. The "all" row's ICC intervals are therefore a
**bootstrap over whole poses** (:data:`BOOTSTRAP_RESAMPLES` resamples of the poses with replacement,
seeded by :data:`BOOTSTRAP_SEED`, percentile intervals), and every row's Krippendorff's alpha and mean
absolute disagreement get the same pose bootstrap (``alpha_ci``, ``disagreement_ci``). The
per-blendshape ICC rows keep their F-based intervals (their items are the poses).

Poses whose mean absolute disagreement exceeds a threshold (default :data:`FLAG_PCT`) are flagged for
review. Gathering ratings (``effortface agreement SESSION | DIR | --ratings CSV``):

- ``--ratings CSV``: those ratings;
- a folder with ``reliability/ratings.csv`` (plus any per-rater ``reliability/ratings_<rater>.csv``
  written by the Annotate stage's blind round): the lab's blind round;
- otherwise (a session, or a folder without ratings): every rater's key-frame curves
  (``annotations/<rater>.json``) evaluated at the pose frames, the poses being the session's rows of
  ``reliability/poses.csv`` next to it, or else poses proposed from its heart-rate and phase extremes
  (:func:`propose_poses`).
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import os
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path

import numpy as np

from effortface.core.blendshapes import DEFAULT_SET, BlendshapeSet
from effortface.annotate.keyframes import ORIGINS, origin_seconds, read_annotations
from effortface.annotate.reliability import (Pose, Rating, mean_abs_disagreement_pct, read_poses, read_ratings)
from effortface.annotate.video_index import FrameTimes
from effortface.core.errors import UserError
from effortface.core.fileio import refuse_overwrite
from effortface.core.figures import agg_figure
from effortface.core.session.folder import (VIDEO_FRAMES_CSV, Session, list_sessions, read_session, read_session_info,
                                            read_video_frames)

#: poses whose mean absolute disagreement is above this (% of the weight range) are flagged
FLAG_PCT = 15.0
#: default size of a reliability round (the paper's 18 poses)
N_POSES = 18
RELIABILITY_DIR = "reliability"
LOA_Z = 1.96
#: resamples of the pose bootstrap (confidence intervals of the "all" row, alpha and disagreement)
BOOTSTRAP_RESAMPLES = 2000
#: seed of the pose bootstrap: the same ratings give the same intervals
BOOTSTRAP_SEED = 0


# ------------------------------------------------------------------------------------ statistics
@dataclasses.dataclass(frozen=True)
class AnovaTwoWay:
    """Mean squares of a two-way ANOVA without replication (subjects x raters).

    Attributes
    ----------
    ms_rows : float
        Between subjects (Shrout & Fleiss BMS).
    ms_cols : float
        Between raters (JMS).
    ms_error : float
        Residual (EMS).
    n, k : int
        Subjects and raters.
    """

    ms_rows: float
    ms_cols: float
    ms_error: float
    n: int
    k: int


def anova_two_way(x: np.ndarray) -> AnovaTwoWay:
    """Mean squares of a complete ``(n subjects, k raters)`` table.

    Raises
    ------
    ValueError
        If the table has missing values or fewer than 2 subjects or raters.
    """
    x = np.asarray(x, dtype=float)
    if x.ndim != 2 or min(x.shape) < 2 or not np.all(np.isfinite(x)):
        raise ValueError(f"ratings table: expected a complete table of >= 2 subjects x >= 2 raters, found shape {x.shape}")
    n, k = x.shape
    grand = x.mean()
    ss_rows = k * np.sum((x.mean(axis=1) - grand) ** 2)
    ss_cols = n * np.sum((x.mean(axis=0) - grand) ** 2)
    ss_error = np.sum((x - grand) ** 2) - ss_rows - ss_cols
    return AnovaTwoWay(ss_rows / (n - 1), ss_cols / (k - 1), ss_error / ((n - 1) * (k - 1)), n, k)


def icc_a1(x: np.ndarray) -> float:
    """ICC(A,1): absolute agreement of single ratings, two-way model (McGraw & Wong 1996 case 2A/3A).

    ``(MSR - MSE) / (MSR + (k - 1) MSE + k / n (MSC - MSE))``; NaN when the denominator is 0.
    """
    a = anova_two_way(x)
    den = a.ms_rows + (a.k - 1) * a.ms_error + a.k / a.n * (a.ms_cols - a.ms_error)
    return float((a.ms_rows - a.ms_error) / den) if den > 0 else math.nan


def icc_c1(x: np.ndarray) -> float:
    """ICC(C,1): consistency of single ratings, two-way model: ``(MSR - MSE) / (MSR + (k - 1) MSE)``."""
    a = anova_two_way(x)
    den = a.ms_rows + (a.k - 1) * a.ms_error
    return float((a.ms_rows - a.ms_error) / den) if den > 0 else math.nan


#: Confidence level of the ICC intervals.
ICC_CONFIDENCE = 0.95


def icc_c1_ci(x: np.ndarray, confidence: float = ICC_CONFIDENCE) -> tuple[float, float]:
    """Confidence interval of ICC(C,1) (McGraw & Wong 1996, Table 7, case 3; Shrout & Fleiss ICC(3,1)).

    With ``F = MSR / MSE``, ``F_L = F / F_{1-a/2}(n-1, (n-1)(k-1))`` and
    ``F_U = F * F_{1-a/2}((n-1)(k-1), n-1)``, the bounds are ``(F_L - 1) / (F_L + k - 1)`` and
    ``(F_U - 1) / (F_U + k - 1)``.

    Returns
    -------
    (lower, upper) : tuple of float
        NaN when the interval is undefined (no residual variance).
    """
    from scipy import stats

    a = anova_two_way(x)
    q = 1 - (1 - confidence) / 2
    df_rows, df_error = a.n - 1, (a.n - 1) * (a.k - 1)
    if not a.ms_error > 0:
        return math.nan, math.nan
    f = a.ms_rows / a.ms_error
    f_low = f / stats.f.ppf(q, df_rows, df_error)
    f_up = f * stats.f.ppf(q, df_error, df_rows)
    return float((f_low - 1) / (f_low + a.k - 1)), float((f_up - 1) / (f_up + a.k - 1))


def icc_a1_ci(x: np.ndarray, confidence: float = ICC_CONFIDENCE) -> tuple[float, float]:
    """Confidence interval of ICC(A,1) (McGraw & Wong 1996, Table 7, case 2A; Shrout & Fleiss ICC(2,1)).

    With ``r`` = ICC(A,1), ``a = k r / (n (1 - r))``, ``b = 1 + k r (n - 1) / (n (1 - r))`` and the
    Satterthwaite degrees of freedom ``v = (a MSC + b MSE)^2 / ((a MSC)^2 / (k - 1) + (b MSE)^2 /
    ((n - 1)(k - 1)))``: lower ``n (MSR - F* MSE) / (F* (k MSC + (k n - k - n) MSE) + n MSR)`` with
    ``F* = F_{1-a/2}(n - 1, v)``, upper ``n (F* MSR - MSE) / (k MSC + (k n - k - n) MSE + n F* MSR)``
    with ``F* = F_{1-a/2}(v, n - 1)``.

    Returns
    -------
    (lower, upper) : tuple of float
        NaN when the interval is undefined (ICC undefined or 1, no residual variance).
    """
    from scipy import stats

    a = anova_two_way(x)
    r = icc_a1(x)
    if not (math.isfinite(r) and r < 1 and a.ms_error > 0):
        return math.nan, math.nan
    n, k = a.n, a.k
    ca = k * r / (n * (1 - r))
    cb = 1 + k * r * (n - 1) / (n * (1 - r))
    v = (ca * a.ms_cols + cb * a.ms_error) ** 2 / (
        (ca * a.ms_cols) ** 2 / (k - 1) + (cb * a.ms_error) ** 2 / ((n - 1) * (k - 1)))
    q = 1 - (1 - confidence) / 2
    spread = k * a.ms_cols + (k * n - k - n) * a.ms_error
    f_low, f_up = stats.f.ppf(q, n - 1, v), stats.f.ppf(q, v, n - 1)
    low = n * (a.ms_rows - f_low * a.ms_error) / (f_low * spread + n * a.ms_rows)
    up = n * (f_up * a.ms_rows - a.ms_error) / (spread + n * f_up * a.ms_rows)
    return float(low), float(up)


def krippendorff_alpha_interval(x: np.ndarray) -> float:
    """Krippendorff's alpha (interval) of a ``(units, raters)`` table, NaN for missing ratings."""
    import krippendorff

    data = np.asarray(x, dtype=float).T  # the package wants raters x units
    if np.unique(data[np.isfinite(data)]).size < 2:
        return math.nan  # alpha is undefined when every rating is the same value
    return float(krippendorff.alpha(reliability_data=data, level_of_measurement="interval"))


def alpha_interval(x: np.ndarray) -> float:
    """Krippendorff's alpha (interval metric) of a ``(units, raters)`` table in closed form (numpy).

    Over the pairable values (units with at least two ratings; n of them in all),
    ``D_o = (1/n) sum_u 2 (m_u sum x^2 - (sum x)^2) / (m_u - 1)`` and
    ``D_e = 2 (n sum x^2 - (sum x)^2) / (n (n - 1))``; ``alpha = 1 - D_o / D_e``. The same value as
    :func:`krippendorff_alpha_interval` (tested), fast enough for a bootstrap. NaN when undefined.
    """
    x = np.asarray(x, dtype=float)
    ok = np.isfinite(x)
    m = ok.sum(axis=1)
    pairable = m >= 2
    if not pairable.any():
        return math.nan
    v, ok, m = np.where(ok, x, 0.0)[pairable], ok[pairable], m[pairable]
    s1, s2 = v.sum(axis=1), (v * v).sum(axis=1)
    n = float(m.sum())
    d_o = float(np.sum(2.0 * (m * s2 - s1 * s1) / (m - 1))) / n
    d_e = 2.0 * (n * float(s2.sum()) - float(s1.sum()) ** 2) / (n * (n - 1.0))
    return 1.0 - d_o / d_e if d_e > 0 else math.nan


def disagreement_pct(cube: np.ndarray) -> float:
    """Mean absolute pairwise difference (% of [0, 1]) of a ``(poses, blendshapes, raters)`` cube:
    per item with two or more ratings the mean ``|w_a - w_b|`` over rater pairs, then the mean over
    items (as :func:`~effortface.annotate.reliability.mean_abs_disagreement_pct`). NaN without items."""
    flat = np.asarray(cube, dtype=float).reshape(-1, cube.shape[-1])
    total, pairs = np.zeros(flat.shape[0]), np.zeros(flat.shape[0])
    for i, j in itertools.combinations(range(flat.shape[1]), 2):
        both = np.isfinite(flat[:, i]) & np.isfinite(flat[:, j])
        total += np.where(both, np.abs(flat[:, i] - flat[:, j]), 0.0)
        pairs += both
    rated = pairs > 0
    return 100.0 * float(np.mean(total[rated] / pairs[rated])) if rated.any() else math.nan


def _complete_icc(table: np.ndarray, icc: Callable[[np.ndarray], float]) -> float:
    """An ICC of the table's complete rows (NaN with fewer than two, or when undefined)."""
    complete = table[np.all(np.isfinite(table), axis=1)]
    if complete.shape[0] < 2:
        return math.nan
    with np.errstate(divide="ignore", invalid="ignore"):
        return float(icc(complete))


def pose_bootstrap(cube: np.ndarray, statistic: Callable[[np.ndarray], float], *,
                   n_resamples: int = BOOTSTRAP_RESAMPLES, seed: int = BOOTSTRAP_SEED,
                   confidence: float = ICC_CONFIDENCE) -> tuple[float, float]:
    """Percentile interval of ``statistic(cube)`` when whole poses are resampled with replacement.

    Parameters
    ----------
    cube : ndarray, shape (poses, ...)
        Ratings with the poses on the first axis (the clusters).
    statistic : callable
        Of a resampled cube (same shape), a float (NaN resamples are left out).
    n_resamples, seed : int
        Resamples and the seed of their draw (the same inputs give the same interval).
    confidence : float
        Coverage of the interval (0.95).

    Returns
    -------
    (lower, upper) : tuple of float
        NaN when fewer than half the resamples give a value.
    """
    rng = np.random.default_rng(seed)
    n = cube.shape[0]
    values = np.array([statistic(cube[rng.integers(0, n, n)]) for _ in range(n_resamples)])
    values = values[np.isfinite(values)]
    if values.size < n_resamples / 2:
        return math.nan, math.nan
    tail = 100.0 * (1.0 - confidence) / 2.0
    low, high = np.percentile(values, [tail, 100.0 - tail])
    return float(low), float(high)


@dataclasses.dataclass(frozen=True)
class BlandAltman:
    """Bland-Altman statistics of rater ``a`` minus rater ``b`` over paired items.

    Attributes
    ----------
    rater_a, rater_b : str
    n : int
        Paired items.
    bias : float
        Mean difference (weight units).
    sd : float
        Standard deviation of the differences (ddof 1).
    loa_low, loa_high : float
        ``bias -+ 1.96 sd``.
    means, diffs : numpy.ndarray
        Per item ``(a + b) / 2`` and ``a - b`` (the plot's points).
    """

    rater_a: str
    rater_b: str
    n: int
    bias: float
    sd: float
    loa_low: float
    loa_high: float
    means: np.ndarray = dataclasses.field(repr=False, compare=False)
    diffs: np.ndarray = dataclasses.field(repr=False, compare=False)


def bland_altman(a: np.ndarray, b: np.ndarray, rater_a: str = "a", rater_b: str = "b") -> BlandAltman:
    """Bland-Altman statistics of paired ratings (pairs with a NaN are left out).

    Raises
    ------
    ValueError
        If fewer than 2 complete pairs remain.
    """
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    ok = np.isfinite(a) & np.isfinite(b)
    if ok.sum() < 2:
        raise ValueError(f"raters {rater_a}, {rater_b}: expected at least 2 paired ratings, found {int(ok.sum())}")
    d, m = a[ok] - b[ok], (a[ok] + b[ok]) / 2
    bias, sd = float(d.mean()), float(d.std(ddof=1))
    return BlandAltman(rater_a, rater_b, int(ok.sum()), bias, sd, bias - LOA_Z * sd, bias + LOA_Z * sd, m, d)


# ---------------------------------------------------------------------------------------- report
@dataclasses.dataclass(frozen=True)
class ItemStats:
    """Agreement over one group of items (a blendshape, or everything); ``*_ci`` are 95 % confidence
    intervals (lower, upper): the ICCs' F-based for a blendshape and pose-bootstrap for "all";
    ``alpha_ci`` and ``disagreement_ci`` pose-bootstrap for every row (module docstring)."""

    name: str
    n_items: int
    disagreement_pct: float
    icc_a1: float
    icc_c1: float
    alpha: float
    icc_a1_ci: tuple[float, float] = (math.nan, math.nan)
    icc_c1_ci: tuple[float, float] = (math.nan, math.nan)
    alpha_ci: tuple[float, float] = (math.nan, math.nan)
    disagreement_ci: tuple[float, float] = (math.nan, math.nan)


@dataclasses.dataclass
class AgreementReport:
    """The whole report; see the module docstring.

    Attributes
    ----------
    raters, poses, blendshapes : list of str
        What was rated (poses in input order, blendshapes in set order).
    per_pose_pct : dict of str to float
        Mean absolute disagreement of each pose, % of the weight range.
    per_blendshape : list of ItemStats
    overall : ItemStats
    pairs : list of BlandAltman
    flag_pct : float
    flagged : list of str
        Poses above ``flag_pct``.
    incomplete : list of str
        Poses left out of the ICCs because a rater did not rate every blendshape.
    source : str
        Where the ratings came from.
    """

    raters: list[str]
    poses: list[str]
    blendshapes: list[str]
    per_pose_pct: dict[str, float]
    per_blendshape: list[ItemStats]
    overall: ItemStats
    pairs: list[BlandAltman]
    flag_pct: float
    flagged: list[str]
    incomplete: list[str]
    source: str = ""


def ratings_cube(ratings: Sequence[Rating], blendshapes: Sequence[str] | None = None
                 ) -> tuple[np.ndarray, list[str], list[str], list[str]]:
    """Ratings as an array ``(poses, blendshapes, raters)`` with NaN where a rating is missing.

    Returns
    -------
    cube, poses, blendshapes, raters
    """
    poses = list(dict.fromkeys(r.pose_id for r in ratings))
    names = list(blendshapes) if blendshapes else list(dict.fromkeys(r.blendshape for r in ratings))
    raters = sorted({r.rater for r in ratings})
    cube = np.full((len(poses), len(names), len(raters)), np.nan)
    p_i, b_i, r_i = ({v: i for i, v in enumerate(seq)} for seq in (poses, names, raters))
    for r in ratings:
        if r.blendshape in b_i:
            cube[p_i[r.pose_id], b_i[r.blendshape], r_i[r.rater]] = r.weight
    return cube, poses, names, raters


def _item_stats(name: str, table: np.ndarray, ratings: Iterable[Rating]) -> ItemStats:
    """Statistics of one ``(items, raters)`` table; ICCs on its complete rows only."""
    if not np.any(np.isfinite(table).sum(axis=1) >= 2):  # no item rated by two raters: nothing to compare
        return ItemStats(name, int(table.shape[0]), math.nan, math.nan, math.nan, math.nan)
    complete = table[np.all(np.isfinite(table), axis=1)]
    enough = complete.shape[0] >= 2
    nan2 = (math.nan, math.nan)
    return ItemStats(name, int(table.shape[0]), mean_abs_disagreement_pct(ratings),
                     icc_a1(complete) if enough else math.nan, icc_c1(complete) if enough else math.nan,
                     krippendorff_alpha_interval(table), icc_a1_ci(complete) if enough else nan2,
                     icc_c1_ci(complete) if enough else nan2)


def agreement_report(ratings: Sequence[Rating], *, flag_pct: float = FLAG_PCT,
                     blendshapes: BlendshapeSet | None = DEFAULT_SET, source: str = "") -> AgreementReport:
    """Compute the reliability report of blind pose ratings.

    Parameters
    ----------
    ratings : sequence of Rating
        Long-format ratings (``pose_id, rater, blendshape, weight``).
    flag_pct : float
        Flag poses whose mean absolute disagreement (% of [0, 1]) is above this.
    blendshapes : BlendshapeSet or None
        Order of the blendshapes in the report; None keeps the order of first appearance.
        Blendshapes outside the set are an error.
    source : str
        Where the ratings came from (printed in the report).

    Returns
    -------
    AgreementReport

    Raises
    ------
    UserError
        If fewer than two raters or two poses are found, if no pose and blendshape is rated by two
        raters, or if a pair of raters shares fewer than 2 rated pose blendshapes.
    """
    ratings = list(ratings)
    if blendshapes is not None:
        for r in ratings:
            blendshapes.index(r.blendshape)  # UserError for a name outside the set
    names = [n for n in blendshapes.names if any(r.blendshape == n for r in ratings)] if blendshapes else None
    cube, poses, names, raters = ratings_cube(ratings, names)
    if len(raters) < 2 or len(poses) < 2:
        raise UserError(f"ratings{f' ({source})' if source else ''}: expected at least 2 raters and 2 poses, "
                        f"found {len(raters)} raters and {len(poses)} poses")
    per_pose = {p: pct for p in poses if not math.isnan(pct := _pose_pct(ratings, p))}
    if not per_pose:
        raise UserError(f"ratings{f' ({source})' if source else ''}: expected at least one pose and blendshape "
                        f"rated by two raters, found none ({len(raters)} raters never rated the same pose)")
    per_shape = [_with_bootstrap(_item_stats(n, cube[:, j, :], [r for r in ratings if r.blendshape == n]),
                                 cube[:, j:j + 1, :], pooled=False)
                 for j, n in enumerate(names)]
    overall = _with_bootstrap(_item_stats("all", cube.reshape(-1, len(raters)), ratings), cube, pooled=True)
    flat = cube.reshape(-1, len(raters))
    pairs = []
    for i, j in itertools.combinations(range(len(raters)), 2):
        shared = int(np.sum(np.isfinite(flat[:, i]) & np.isfinite(flat[:, j])))
        if shared < 2:
            raise UserError(f"ratings{f' ({source})' if source else ''}: expected raters {raters[i]} and "
                            f"{raters[j]} to rate at least 2 pose blendshapes in common (for Bland-Altman), "
                            f"found {shared}")
        pairs.append(bland_altman(flat[:, i], flat[:, j], raters[i], raters[j]))
    incomplete = [p for i, p in enumerate(poses) if not np.all(np.isfinite(cube[i]))]
    flagged = [p for p, pct in per_pose.items() if pct > flag_pct]
    return AgreementReport(raters, poses, names, per_pose, per_shape, overall, pairs, flag_pct,
                           flagged, incomplete, source)


def _with_bootstrap(stats: ItemStats, cube: np.ndarray, *, pooled: bool) -> ItemStats:
    """``stats`` with pose-bootstrap intervals for alpha and disagreement, and for the ICCs when
    ``pooled`` (the "all" row, whose items are pose x blendshape)."""
    if math.isnan(stats.alpha) and math.isnan(stats.disagreement_pct):
        return stats
    n_raters = cube.shape[-1]

    def flat(c: np.ndarray) -> np.ndarray:
        return c.reshape(-1, n_raters)

    stats = dataclasses.replace(stats, alpha_ci=pose_bootstrap(cube, lambda c: alpha_interval(flat(c))),
                                disagreement_ci=pose_bootstrap(cube, disagreement_pct))
    if pooled and not math.isnan(stats.icc_a1):
        stats = dataclasses.replace(
            stats, icc_a1_ci=pose_bootstrap(cube, lambda c: _complete_icc(flat(c), icc_a1)),
            icc_c1_ci=pose_bootstrap(cube, lambda c: _complete_icc(flat(c), icc_c1)))
    return stats


def _pose_pct(ratings: Sequence[Rating], pose: str) -> float:
    """Mean absolute disagreement of one pose, NaN if no blendshape of it has two raters."""
    try:
        return mean_abs_disagreement_pct([r for r in ratings if r.pose_id == pose])
    except ValueError:
        return math.nan


def format_report(report: AgreementReport) -> str:
    """The report as plain text (what ``effortface agreement`` prints)."""
    lines = [f"Inter-rater agreement{f' ({report.source})' if report.source else ''}",
             f"raters: {', '.join(report.raters)}   poses: {len(report.poses)}   "
             f"blendshapes: {', '.join(report.blendshapes)}", ""]
    lines += ["Per pose (mean |difference|, % of the weight range):"]
    for pose, pct in report.per_pose_pct.items():
        flag = "  FLAGGED for review" if pose in report.flagged else ""
        lines.append(f"  {pose:<12} {pct:6.1f} %{flag}")
    lines += ["", f"  {'blendshape':<14} {'items':>5} {'diff %':>7} {'95 % CI':>14} {'ICC(A,1)':>9} "
                  f"{'95 % CI':>14} {'ICC(C,1)':>9} {'95 % CI':>14} {'alpha':>7} {'95 % CI':>14}"]
    for s in [*report.per_blendshape, report.overall]:
        lines.append(f"  {s.name:<14} {s.n_items:>5} {s.disagreement_pct:7.1f} {format_pct_ci(s.disagreement_ci):>14} "
                     f"{s.icc_a1:9.3f} {format_ci(s.icc_a1_ci):>14} {s.icc_c1:9.3f} {format_ci(s.icc_c1_ci):>14} "
                     f"{s.alpha:7.3f} {format_ci(s.alpha_ci):>14}")
    lines.append(f"  (95 % CI: per blendshape the ICCs' F-based intervals of McGraw & Wong 1996; the \"all\" "
                 f"row's ICCs, every alpha and diff % by a bootstrap over whole poses, "
                 f"{BOOTSTRAP_RESAMPLES:,} resamples, seed {BOOTSTRAP_SEED}; few poses give wide intervals)")
    lines += ["", "Bland-Altman per rater pair (weight units, a - b):"]
    for p in report.pairs:
        lines.append(f"  {p.rater_a}-{p.rater_b}  n={p.n:<4} bias {p.bias:+.3f}   "
                     f"limits of agreement {p.loa_low:+.3f} .. {p.loa_high:+.3f}")
    lines += ["", f"Flagged poses (over {report.flag_pct:g} %): {', '.join(report.flagged) or 'none'}"]
    if report.incomplete:
        lines.append(f"Poses missing a rating (left out of the ICCs): {', '.join(report.incomplete)}")
    return "\n".join(lines) + "\n"


def format_ci(ci: tuple[float, float]) -> str:
    """An interval as ``[0.61, 0.92]`` (``[nan, nan]`` when undefined)."""
    return f"[{ci[0]:.2f}, {ci[1]:.2f}]"


def format_pct_ci(ci: tuple[float, float]) -> str:
    """A percentage interval as ``[8.1, 12.4]`` (``[nan, nan]`` when undefined)."""
    return f"[{ci[0]:.1f}, {ci[1]:.1f}]"


def save_bland_altman_png(report: AgreementReport, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """Draw the Bland-Altman plot of every rater pair into a PNG (matplotlib, Agg backend).

    Raises
    ------
    FileExistsError
        If ``path`` exists and ``overwrite`` is False.
    UserError
        If matplotlib is not installed.
    """
    path = refuse_overwrite(path, overwrite=overwrite)
    fig = agg_figure((4.2 * len(report.pairs), 3.6), layout="tight")
    axes = fig.subplots(1, len(report.pairs), squeeze=False)
    for ax, p in zip(axes[0], report.pairs):
        ax.scatter(p.means, p.diffs, s=10, alpha=0.6)
        for y, style in ((p.bias, "-"), (p.loa_low, "--"), (p.loa_high, "--")):
            ax.axhline(y, color="k", linestyle=style, linewidth=1)
        ax.set(title=f"{p.rater_a} - {p.rater_b}", xlabel="mean weight", ylabel="difference",
               xlim=(0, 1), ylim=(-1, 1))
    fig.savefig(path, dpi=100)
    return path


# --------------------------------------------------------------------------- gathering ratings
def propose_poses(session: Session, n: int = N_POSES, *, min_gap_s: float = 5.0,
                  first_id: int = 1) -> list[Pose]:
    """Propose representative frames of a session from its heart-rate and phase extremes.

    Candidates, in priority order: the highest and lowest valid heart rate, then for each exercise
    phase its end (accumulated effort), its heart-rate peak and its start; then evenly spaced times.
    A candidate closer than ``min_gap_s`` to an accepted one is skipped.

    Parameters
    ----------
    session : Session
        A session with video (``video_frames.csv``).
    n : int
        Poses wanted.
    min_gap_s : float
        Minimum time between two poses.
    first_id : int
        Number of the first ``poseNN`` id.

    Raises
    ------
    UserError
        If the session has no video frames.
    """
    if not session.frame_times_s:
        raise UserError(f"{session.path}: expected a session with video_frames.csv, found no video frames")
    clock = FrameTimes(session.frame_times_s)
    chosen: list[float] = []
    for t in _pose_candidates(session, clock, n):
        if len(chosen) >= n:
            break
        if all(abs(t - c) >= min_gap_s for c in chosen):
            chosen.append(t)
    frames = sorted({clock.frame_at(t) for t in chosen})
    return [Pose(f"pose{first_id + i:02d}", session.info.session_id, f, clock.t_at(f))
            for i, f in enumerate(frames)]


def _pose_candidates(session: Session, clock: FrameTimes, n: int) -> list[float]:
    """Candidate pose times in priority order (see :func:`propose_poses`)."""
    hr = [(h.t_s, h.hr_bpm) for h in session.heart_rate if h.valid and h.hr_bpm]
    out: list[float] = []
    if hr:
        t, bpm = np.array(hr).T
        out += [float(t[np.argmax(bpm)]), float(t[np.argmin(bpm)])]
    starts = {e.label: e.t_s for e in session.events if e.kind == "phase_start"}
    for e in session.events:
        if e.kind == "phase_end" and e.label in starts:
            t0, t1 = starts[e.label], e.t_s
            inside = [(t, b) for t, b in hr if t0 <= t <= t1]
            peak = [max(inside, key=lambda tb: tb[1])[0]] if inside else []
            out += [t1 - 0.5, *peak, t0 + 2.0]
    out += list(np.linspace(clock.t_s[0], clock.duration_s, max(n, 2) * 2))
    return [min(max(t, clock.t_s[0]), clock.duration_s) for t in out]


def ratings_from_keyframes(folder: str | os.PathLike, poses: Sequence[Pose]) -> list[Rating]:
    """Every rater's key-frame curves of a session evaluated at the pose frames.

    Parameters
    ----------
    folder : path-like
        A session folder with ``annotations/<rater>.json``.
    poses : sequence of Pose
        Poses of this session (others are ignored).

    Returns
    -------
    list of Rating
        Blendshapes a rater has not keyed are left out (missing, not zero), and so is a pose whose
        label is a key the rater accepted from the machine and did not edit (the machine's, not theirs).
    """
    folder = Path(folder)
    sid = read_session(folder).info.session_id
    mine = [p for p in poses if p.session_id == sid]
    out: list[Rating] = []
    for path in sorted((folder / "annotations").glob("*.json")):
        ann = read_annotations(path, session_id=sid, rater=path.stem)  # not a copy of another's file
        frames = np.array([p.frame for p in mine], dtype=float)
        for name in ann.blendshapes.names:
            values = ann.tracks[name].evaluate_human(frames)
            out += [Rating(p.pose_id, ann.rater, name, float(round(w, 4)))
                    for p, w in zip(mine, values) if np.isfinite(w)]
    return out


def origin_seconds_by_rater(sessions: Sequence[str | os.PathLike]) -> dict[str, dict[str, int]]:
    """Seconds of each rater's labels by key origin (typed, machine, edited), over every blendshape of
    the sessions' ``annotations/<rater>.json`` (see :func:`effortface.annotate.keyframes.origin_seconds`)."""
    out: dict[str, dict[str, int]] = {}
    for folder in map(Path, sessions):
        session = read_session(folder)
        for path in sorted((folder / "annotations").glob("*.json")):
            ann = read_annotations(path, session_id=session.info.session_id, rater=path.stem)
            counts = out.setdefault(ann.rater, {o: 0 for o in ORIGINS})
            for track in ann.tracks.values():
                for origin, n in origin_seconds(track, session.frame_times_s).items():
                    counts[origin] += n
    return out


def format_origins(counts: dict[str, dict[str, int]]) -> str:
    """One line: each rater's label seconds by origin, e.g. ``R1 typed 2556 s; R4 machine 2552 s (left out)``."""
    parts = []
    for rater, n in counts.items():
        kinds = [f"{o} {n[o]} s" for o in ORIGINS if n[o]]
        parts.append(f"{rater} {', '.join(kinds) or 'no key'}" + (" (machine: left out)" if n["machine"] else ""))
    return "label seconds by key origin: " + "; ".join(parts)


def read_round(folder: str | os.PathLike) -> list[Rating]:
    """The blind round's ratings of a lab folder: ``reliability/ratings.csv`` plus ``ratings_<rater>.csv``.

    Raises
    ------
    UserError
        If a rater's rating appears twice across the files (names the file).
    """
    rel = Path(folder) / RELIABILITY_DIR
    files = [p for p in [rel / "ratings.csv", *sorted(rel.glob("ratings_*.csv"))] if p.is_file()]
    out: list[Rating] = []
    seen: set[tuple[str, str, str]] = set()
    for path in files:
        for r in read_ratings(path, DEFAULT_SET):
            key = (r.pose_id, r.rater, r.blendshape)
            if key in seen:
                raise UserError(f"{path}: expected each pose, rater and blendshape once, found {key} again")
            seen.add(key)
            out.append(r)
    return out


def gather_ratings(target: str | os.PathLike, *, n_poses: int = N_POSES) -> tuple[list[Rating], str]:
    """Ratings for ``effortface agreement SESSION | DIR`` (see the module docstring).

    Returns
    -------
    ratings : list of Rating
    source : str
        A one-line description of where they came from.

    Raises
    ------
    UserError
        If ``target`` is neither a session folder nor a folder of sessions, or holds no ratings.
    """
    target = Path(target)
    if not target.is_dir():
        raise UserError(f"{target}: expected a session folder or a folder of sessions, "
                        f"found {'a file' if target.exists() else 'nothing'}")
    if (target / RELIABILITY_DIR / "ratings.csv").is_file() or list((target / RELIABILITY_DIR).glob("ratings_*.csv")):
        return read_round(target), f"blind round in {target / RELIABILITY_DIR}"
    sessions = [target] if (target / "session.json").is_file() else list_sessions(target)
    if not sessions:
        raise UserError(f"{target}: expected a session folder or a folder of sessions, found neither")
    poses = _poses_for(target, sessions, n_poses)
    ratings = [r for s in sessions for r in ratings_from_keyframes(s, poses)]
    if not ratings:
        raise UserError(f"{target}: expected annotations/<rater>.json files with keys a person typed or "
                        f"edited, found none")
    return ratings, (f"raters' key-frames at {len(poses)} pose frames in {target}; "
                     f"{format_origins(origin_seconds_by_rater(sessions))}")


def _poses_for(target: Path, sessions: list[Path], n_poses: int) -> list[Pose]:
    """Poses from a nearby ``reliability/poses.csv``, else proposed across the sessions."""
    for rel in (target / RELIABILITY_DIR, target.parent / RELIABILITY_DIR):
        if (rel / "poses.csv").is_file():
            frames = frames_by_session(sessions)
            poses = [p for p in read_poses(rel / "poses.csv", frames) if p.session_id in frames]
            if poses:
                return poses
    per_session = max(1, math.ceil(n_poses / len(sessions)))
    poses = []
    for s in sessions:
        poses += propose_poses(read_session(s), per_session, first_id=len(poses) + 1)
    return poses[:n_poses]


def gather_poses(target: str | os.PathLike, *, n_poses: int = N_POSES) -> list[Pose]:
    """The poses :func:`gather_ratings` rates for ``target``: the blind round's ``poses.csv``, else those of
    :func:`_poses_for` (empty when ``target`` holds no session)."""
    target = Path(target)
    rel = target / RELIABILITY_DIR
    if (rel / "ratings.csv").is_file() or list(rel.glob("ratings_*.csv")):
        frames = frames_by_session(list_sessions(target)) if target.is_dir() else {}
        return read_poses(rel / "poses.csv", frames) if (rel / "poses.csv").is_file() else []
    sessions = [target] if (target / "session.json").is_file() else list_sessions(target)
    return _poses_for(target, sessions, n_poses) if sessions else []


def frames_by_session(sessions: Iterable[str | os.PathLike]) -> dict[str, list[float]]:
    """``session_id -> frame times (s)`` of the sessions' ``video_frames.csv`` (empty without video), the
    frames a ``poses.csv`` must agree with (:func:`effortface.annotate.reliability.read_poses`)."""
    out: dict[str, list[float]] = {}
    for folder in map(Path, sessions):
        frames = folder / VIDEO_FRAMES_CSV
        out[read_session_info(folder).session_id] = read_video_frames(frames) if frames.is_file() else []
    return out


# ---------------------------------------------------------------------------- the machine rater
#: the machine's rater code in ratings (never a human's code: the Annotate stage refuses it)
MACHINE_RATER = "machine"
#: how the report names the machine
MACHINE_LABEL = "machine rater (MediaPipe face landmarker)"
#: name of the humans' mean as a reference
HUMAN_MEAN = "human mean"
#: bootstrap resamples of the machine's confidence intervals, and their seed
N_BOOT = 1000
BOOT_SEED = 0


def machine_ratings(target: str | os.PathLike, poses: Sequence[Pose]) -> tuple[list[Rating], list[str]]:
    """The machine track's four weights at the pose frames (nearest frame in time), as rater ``machine``.

    Parameters
    ----------
    target : path-like
        A session folder or a folder of sessions (those with ``machine/face_landmarker.csv`` count).
    poses : sequence of Pose
        The poses rated; each is looked up in its session's track.

    Returns
    -------
    ratings : list of Rating
        Nothing for a pose whose session has no track or whose nearest frame has no face.
    no_face : list of str
        Pose ids whose nearest frame has no face.
    """
    from effortface.annotate.machine.track import FOUR, MachineTrack, read_machine_track

    target = Path(target)
    if not target.is_dir():
        return [], []
    sessions = [target] if (target / "session.json").is_file() else list_sessions(target)
    by_id = {read_session_info(s).session_id: s for s in sessions}
    out: list[Rating] = []
    no_face: list[str] = []
    tracks: dict[str, MachineTrack | None] = {}
    for pose in poses:
        folder = by_id.get(pose.session_id)
        if folder is None:
            continue
        if pose.session_id not in tracks:
            tracks[pose.session_id] = read_machine_track(folder)
        track = tracks[pose.session_id]
        if track is None or track.t_s.size == 0:
            continue
        i = int(np.argmin(np.abs(track.t_s - pose.t_s)))
        if not track.face[i]:
            no_face.append(pose.pose_id)
            continue
        out += [Rating(pose.pose_id, MACHINE_RATER, name, float(round(w, 4)))
                for name, w in zip(FOUR, track.weights[i]) if np.isfinite(w)]
    return out, no_face


@dataclasses.dataclass(frozen=True)
class MachineStats:
    """The machine against one reference over one group of items, each figure with its 95 % CI.

    Attributes
    ----------
    reference : str
        A human rater's code or :data:`HUMAN_MEAN`.
    name : str
        A blendshape, or ``"all"`` (pooled pose-blendshape items).
    n_items : int
        Items where both the machine and the reference have a value.
    icc_a1, alpha, mad_pct : float
        ICC(A,1) of the two, Krippendorff's alpha (interval) and the mean absolute difference in % of
        the weight range.
    icc_a1_ci, alpha_ci, mad_pct_ci : tuple of float
        Percentile bootstrap intervals over poses.
    """

    reference: str
    name: str
    n_items: int
    icc_a1: float
    alpha: float
    mad_pct: float
    icc_a1_ci: tuple[float, float]
    alpha_ci: tuple[float, float]
    mad_pct_ci: tuple[float, float]


@dataclasses.dataclass
class MachineReport:
    """The machine rater's section of the report (see :func:`machine_report`).

    Attributes
    ----------
    label : str
    n_poses : int
        Poses with a machine value.
    no_face : list of str
        Poses whose nearest frame has no face (no machine value).
    stats : list of MachineStats
        Per reference (each human, then the human mean), per blendshape then pooled.
    n_boot, seed : int
        The bootstrap's resamples and seed.
    in_mean : bool
        True when the machine was also counted as a rater in the main report (``--machine-in-mean``).
    """

    label: str
    n_poses: int
    no_face: list[str]
    stats: list[MachineStats]
    n_boot: int
    seed: int
    in_mean: bool = False


def alpha_interval_pairs(a: np.ndarray, b: np.ndarray) -> float:
    """Krippendorff's alpha (interval) of two raters over complete pairs (closed form, vectorised).

    With the ``N = 2 n`` pairable values, ``D_o = 2 sum (a - b)^2 / N`` and
    ``D_e = 2 sum (v - mean v)^2 / (N - 1)``; alpha is ``1 - D_o / D_e`` (NaN when every value is equal).
    Equal to ``krippendorff.alpha`` on complete data.
    """
    a, b = np.asarray(a, float), np.asarray(b, float)
    v = np.concatenate([a, b])
    n_values = v.size
    d_e = 2 * np.sum((v - v.mean()) ** 2) / (n_values - 1) if n_values > 1 else 0.0
    if not d_e > 0:
        return math.nan
    return float(1 - (2 * np.sum((a - b) ** 2) / n_values) / d_e)


def _pair_figures(a: np.ndarray, b: np.ndarray) -> tuple[float, float, float]:
    """ICC(A,1), alpha and MAD % of paired values (NaN pairs dropped)."""
    ok = np.isfinite(a) & np.isfinite(b)
    a, b = a[ok], b[ok]
    if a.size < 2:
        return math.nan, math.nan, 100.0 * float(np.mean(np.abs(a - b))) if a.size else math.nan
    return icc_a1(np.column_stack([a, b])), alpha_interval_pairs(a, b), 100.0 * float(np.mean(np.abs(a - b)))


def _percentile_ci(values: np.ndarray) -> tuple[float, float]:
    """2.5th and 97.5th percentiles of the finite values (NaN when none)."""
    v = values[np.isfinite(values)]
    return (math.nan, math.nan) if v.size == 0 else (float(np.percentile(v, 2.5)), float(np.percentile(v, 97.5)))


def machine_stats(machine: np.ndarray, reference: np.ndarray, *, reference_name: str, names: Sequence[str],
                  n_boot: int = N_BOOT, seed: int = BOOT_SEED) -> list[MachineStats]:
    """The machine against one reference, per blendshape and pooled, with bootstrap CIs over poses.

    Parameters
    ----------
    machine, reference : numpy.ndarray, shape (poses, blendshapes)
        NaN where a value is missing.
    reference_name : str
    names : sequence of str
        The blendshapes (columns).
    n_boot : int
        Resamples of the poses (with replacement); each resample keeps a pose's blendshapes together.
    seed : int
        Seed of the resampling (same seed, same intervals).

    Returns
    -------
    list of MachineStats
        One per blendshape, then ``"all"``.
    """
    rng = np.random.default_rng(seed)
    n_poses = machine.shape[0]
    idx = rng.integers(0, n_poses, size=(n_boot, n_poses))
    out = []
    for j, name in enumerate([*names, "all"]):
        cols = slice(None) if name == "all" else slice(j, j + 1)
        m, r = machine[:, cols], reference[:, cols]
        figures = _pair_figures(m.ravel(), r.ravel())
        boot = np.array([_pair_figures(m[i].ravel(), r[i].ravel()) for i in idx]).reshape(-1, 3)
        n_items = int(np.sum(np.isfinite(m) & np.isfinite(r)))
        out.append(MachineStats(reference_name, name, n_items, *figures,
                                *(_percentile_ci(boot[:, c]) for c in range(3))))
    return out


def machine_report(human: Sequence[Rating], machine: Sequence[Rating], *, no_face: Sequence[str] = (),
                   blendshapes: BlendshapeSet = DEFAULT_SET, n_boot: int = N_BOOT, seed: int = BOOT_SEED,
                   in_mean: bool = False) -> MachineReport | None:
    """The machine rater against each human and against the humans' mean (the machine never in that mean).

    Parameters
    ----------
    human : sequence of Rating
        The humans' ratings (a rating by :data:`MACHINE_RATER` is left out).
    machine : sequence of Rating
        The machine's ratings of the same poses (:func:`machine_ratings`).
    no_face : sequence of str
        Poses without a face (reported).
    blendshapes : BlendshapeSet
    n_boot, seed : int
        Bootstrap resamples and seed.
    in_mean : bool
        Recorded only: whether the caller also counted the machine in the main report.

    Returns
    -------
    MachineReport or None
        None when the machine rated no pose that a human rated.
    """
    human = [r for r in human if r.rater != MACHINE_RATER]
    rated = {r.pose_id for r in machine}
    poses = [p for p in dict.fromkeys(r.pose_id for r in human) if p in rated]
    if not poses:
        return None
    names = [n for n in blendshapes.names if any(r.blendshape == n for r in human)]
    pose_set = set(poses)
    cube, poses_h, names, raters = ratings_cube([r for r in human if r.pose_id in pose_set], names)
    m_cube, _, _, _ = ratings_cube([r for r in machine if r.pose_id in pose_set], names)
    m_cube = _align(m_cube[:, :, 0], [r.pose_id for r in machine if r.pose_id in pose_set], poses_h)
    stats: list[MachineStats] = []
    counts = np.isfinite(cube).sum(axis=2)
    mean = np.where(counts > 0, np.nansum(cube, axis=2) / np.maximum(counts, 1), np.nan)
    for name, ref in [*((rater, cube[:, :, k]) for k, rater in enumerate(raters)), (HUMAN_MEAN, mean)]:
        stats += machine_stats(m_cube, ref, reference_name=name, names=names, n_boot=n_boot, seed=seed)
    return MachineReport(MACHINE_LABEL, len(poses), list(no_face), stats, n_boot, seed, in_mean)


def _align(values: np.ndarray, order: list[str], poses: list[str]) -> np.ndarray:
    """Rows of ``values`` (in first-appearance order of ``order``) re-ordered to ``poses``."""
    first = list(dict.fromkeys(order))
    out = np.full((len(poses), values.shape[1]), np.nan)
    for i, p in enumerate(poses):
        if p in first:
            out[i] = values[first.index(p)]
    return out


def machine_summary_line(report: MachineReport) -> str:
    """One line like the humans' overall row: the machine against the human mean, every blendshape pooled
    (items, ICC(A,1) with its 95 % CI, alpha, mean absolute difference in % of the weight range); the app's
    report and ``effortface agreement`` both show it."""
    pooled = next((st for st in report.stats if st.reference == HUMAN_MEAN and st.name == "all"), None)
    if pooled is None:
        return "Machine against the human mean: no pose rated by both"
    return (f"Machine against the human mean, all blendshapes: n {pooled.n_items}, ICC(A,1) "
            f"{pooled.icc_a1:.2f} {format_ci(pooled.icc_a1_ci)}, alpha {pooled.alpha:.2f}, MAD "
            f"{pooled.mad_pct:.1f} % of the range")


def format_machine_report(report: MachineReport) -> str:
    """The machine rater's section as plain text (printed after the humans' report): its one-line summary
    (:func:`machine_summary_line`) first, then the table against each human and the human mean."""
    mean_note = ("also counted as a rater above (--machine-in-mean)" if report.in_mean
                 else "not in the human mean")
    lines = ["", f"{report.label[0].upper()}{report.label[1:]}: apart from the humans ({mean_note})",
             machine_summary_line(report),
             f"machine/face_landmarker.csv at the pose frames (nearest frame): {report.n_poses} poses; "
             f"poses without a face: {', '.join(report.no_face) or 'none'}",
             "", f"  {'against':<12} {'blendshape':<14} {'items':>5} {'ICC(A,1)':>9} {'95 % CI':>14} "
                 f"{'alpha':>7} {'95 % CI':>14} {'MAD %':>6} {'95 % CI':>14}"]
    for s in report.stats:
        mad_ci = f"[{s.mad_pct_ci[0]:.1f}, {s.mad_pct_ci[1]:.1f}]"
        lines.append(f"  {s.reference:<12} {s.name:<14} {s.n_items:>5} {s.icc_a1:9.3f} {format_ci(s.icc_a1_ci):>14} "
                     f"{s.alpha:7.3f} {format_ci(s.alpha_ci):>14} {s.mad_pct:6.1f} {mad_ci:>14}")
    lines.append(f"  (95 % CI: percentile bootstrap over poses, {report.n_boot} resamples, seed {report.seed}; "
                 f"MAD %: mean |machine - reference| in % of the weight range)")
    return "\n".join(lines) + "\n"
