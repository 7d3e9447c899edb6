"""Confidence intervals that respect the design: bootstrap over whole poses (seeded) for the "all"
row, and intervals for alpha and the mean absolute disagreement."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import effortface.annotate.agreement as ag
from effortface.annotate.reliability import Rating, mean_abs_disagreement_pct, read_ratings

RATINGS = Path(__file__).resolve().parents[2] / "sample_sessions" / "reliability" / "ratings.csv"


def _cube(seed: int = 1, poses: int = 18, shapes: int = 4, raters: int = 3, missing: float = 0.0) -> np.ndarray:
    """Ratings whose disagreement is shared by every blendshape of a pose (a pose is hard or easy)."""
    rng = np.random.default_rng(seed)
    truth = rng.uniform(0.1, 0.9, (poses, shapes, 1))
    hardness = rng.gamma(1.0, 0.08, (poses, 1, 1))  # per pose, the same for its blendshapes
    cube = np.clip(truth + hardness * rng.standard_normal((poses, shapes, raters)), 0, 1)
    cube[rng.uniform(size=cube.shape) < missing] = np.nan
    return cube


@pytest.mark.parametrize("missing", [0.0, 0.15])
def test_closed_form_alpha_equals_the_krippendorff_package(missing: float) -> None:
    table = _cube(missing=missing).reshape(-1, 3)
    assert ag.alpha_interval(table) == pytest.approx(ag.krippendorff_alpha_interval(table), abs=1e-12)


def test_cube_disagreement_equals_the_ratings_function() -> None:
    cube = _cube(missing=0.1)
    ratings = [Rating(f"p{p}", f"R{r}", f"b{b}", float(cube[p, b, r]))
               for p, b, r in zip(*np.nonzero(np.isfinite(cube)))]
    assert ag.disagreement_pct(cube) == pytest.approx(mean_abs_disagreement_pct(ratings), abs=1e-12)


def test_bootstrap_is_deterministic_with_its_seed_and_moves_with_another() -> None:
    cube = _cube()
    a = ag.pose_bootstrap(cube, ag.disagreement_pct, n_resamples=500)
    assert a == ag.pose_bootstrap(cube, ag.disagreement_pct, n_resamples=500)
    assert a != ag.pose_bootstrap(cube, ag.disagreement_pct, n_resamples=500, seed=1)


def test_bootstrap_of_a_pose_mean_equals_a_hand_written_percentile_bootstrap() -> None:
    """Known case: the mean over poses of a per-pose value, resampled by the same draws."""
    cube = _cube()
    per_pose = np.array([ag.disagreement_pct(cube[p:p + 1]) for p in range(cube.shape[0])])
    rng = np.random.default_rng(7)
    means = [per_pose[rng.integers(0, 18, 18)].mean() for _ in range(1000)]
    expected = tuple(np.percentile(means, [2.5, 97.5]))
    got = ag.pose_bootstrap(cube, ag.disagreement_pct, n_resamples=1000, seed=7)
    np.testing.assert_allclose(got, expected, rtol=1e-12)  # every pose has 4 items: same weights


def test_identical_poses_give_a_point_interval() -> None:
    cube = np.repeat(_cube()[:1], 10, axis=0)
    low, high = ag.pose_bootstrap(cube, ag.disagreement_pct, n_resamples=200)
    assert low == pytest.approx(high) == pytest.approx(ag.disagreement_pct(cube))


def test_pose_clusters_widen_the_pooled_interval() -> None:
    """When a pose's blendshapes share its difficulty, resampling items as if independent understates
    the uncertainty: the pose bootstrap of the pooled disagreement is wider."""
    cube = _cube(seed=4)
    by_pose = ag.pose_bootstrap(cube, ag.disagreement_pct, n_resamples=1000)
    as_items = ag.pose_bootstrap(cube.reshape(-1, 1, 3), ag.disagreement_pct, n_resamples=1000)
    assert by_pose[1] - by_pose[0] > 1.3 * (as_items[1] - as_items[0])


def test_sample_lab_report_has_intervals_for_every_statistic() -> None:
    if not RATINGS.is_file():
        pytest.skip(f"sample ratings not found: {RATINGS}")
    report = ag.agreement_report(read_ratings(RATINGS))
    for s in [*report.per_blendshape, report.overall]:
        for value, ci in ((s.alpha, s.alpha_ci), (s.disagreement_pct, s.disagreement_ci),
                          (s.icc_a1, s.icc_a1_ci), (s.icc_c1, s.icc_c1_ci)):
            assert not math.isnan(ci[0]) and ci[0] <= value <= ci[1], s.name
    # the "all" row's ICC interval respects the poses: wider than the F-based one over 72 items
    flat = ag.ratings_cube(read_ratings(RATINGS))[0].reshape(-1, len(report.raters))
    f_based = ag.icc_a1_ci(flat[np.all(np.isfinite(flat), axis=1)])
    assert report.overall.icc_a1_ci[1] - report.overall.icc_a1_ci[0] > f_based[1] - f_based[0]
    text = ag.format_report(report)
    assert ag.format_ci(report.overall.alpha_ci) in text and ag.format_pct_ci(report.overall.disagreement_ci) in text
    assert "bootstrap over whole poses, 2,000 resamples, seed 0" in text
    again = ag.agreement_report(read_ratings(RATINGS))
    assert again.overall == report.overall  # seeded: the same ratings give the same intervals
