"""The reliability report: ICCs against Shrout & Fleiss 1979 and pingouin, alpha against Krippendorff 2011 and a
hand implementation, Bland-Altman, flagged poses, ratings gathered from key-frames, proposed poses."""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pytest

from effortface.annotate import agreement as ag
from effortface.annotate.keyframes import read_annotations
from effortface.annotate.reliability import Rating, mean_abs_disagreement_pct, read_poses, read_ratings
from effortface.core.errors import UserError
from effortface.core.session.folder import read_session

ROOT = Path(__file__).resolve().parents[2]
SAMPLES = ROOT / "sample_sessions"
RATINGS = SAMPLES / "reliability" / "ratings.csv"

#: Shrout & Fleiss (1979), Table 2: 6 targets rated by 4 judges
SF_TABLE = np.array([[9, 2, 5, 8], [6, 1, 3, 2], [8, 4, 6, 8], [7, 1, 2, 6], [10, 5, 6, 9], [6, 2, 4, 7]], float)


def test_anova_and_icc_match_shrout_fleiss_1979() -> None:
    a = ag.anova_two_way(SF_TABLE)
    # published mean squares (Table 3): BMS 11.24, JMS 32.49, EMS 1.02
    assert (round(a.ms_rows, 2), round(a.ms_cols, 2), round(a.ms_error, 2)) == (11.24, 32.49, 1.02)
    # published: ICC(2,1) = .29 (absolute agreement), ICC(3,1) = .71 (consistency)
    assert round(ag.icc_a1(SF_TABLE), 2) == 0.29
    assert round(ag.icc_c1(SF_TABLE), 2) == 0.71


def _residual_ms_by_least_squares(x: np.ndarray) -> float:
    """Residual mean square of the additive model subject + rater, fitted with dummy variables."""
    n, k = x.shape
    rows, cols = np.meshgrid(np.arange(n), np.arange(k), indexing="ij")
    design = np.column_stack([np.eye(n)[rows.ravel()], np.eye(k)[cols.ravel()][:, 1:]])
    coef, *_ = np.linalg.lstsq(design, x.ravel(), rcond=None)
    resid = x.ravel() - design @ coef
    return float(resid @ resid / ((n - 1) * (k - 1)))


def test_icc_on_the_sample_raters_matches_an_independent_fit() -> None:
    cube, poses, names, raters = ag.ratings_cube(read_ratings(RATINGS))
    x = cube.reshape(-1, len(raters))
    a = ag.anova_two_way(x)
    assert a.ms_error == pytest.approx(_residual_ms_by_least_squares(x), rel=1e-10)
    n, k = x.shape
    var_subjects = np.var(x.mean(axis=1), ddof=1)  # MSR / k
    ms_rows = k * var_subjects
    ms_cols = n * np.var(x.mean(axis=0), ddof=1)
    expected_a = (ms_rows - a.ms_error) / (ms_rows + (k - 1) * a.ms_error + k / n * (ms_cols - a.ms_error))
    assert ag.icc_a1(x) == pytest.approx(expected_a, rel=1e-10)
    assert 0.8 < ag.icc_a1(x) < ag.icc_c1(x) < 0.95  # raters are biased a little: consistency > agreement


@pytest.mark.filterwarnings("ignore::DeprecationWarning", "ignore::FutureWarning")
def test_iccs_match_pingouin_on_the_sample_raters_and_shrout_fleiss() -> None:
    """ICC(A,1) and ICC(C,1) equal pingouin's (single rater, two-way; ICC2 and ICC3 before 0.7)."""
    import pandas as pd
    import pingouin as pg  # the test extra installs it

    cube, *_ = ag.ratings_cube(read_ratings(RATINGS))
    for x in (SF_TABLE, cube.reshape(-1, cube.shape[2]), cube[:, 1, :]):
        n, k = x.shape
        long = pd.DataFrame({"target": np.repeat(np.arange(n), k), "rater": np.tile(np.arange(k), n),
                             "rating": x.ravel()})
        table = pg.intraclass_corr(long, targets="target", raters="rater", ratings="rating")
        # rows: ICC1, ICC2 = ICC(A,1), ICC3 = ICC(C,1), then the k-rater forms (0.7 renamed, same order)
        assert list(table["Type"][1:3]) in (["ICC2", "ICC3"], ["ICC(A,1)", "ICC(C,1)"])
        assert ag.icc_a1(x) == pytest.approx(table["ICC"].iloc[1], abs=1e-12)
        assert ag.icc_c1(x) == pytest.approx(table["ICC"].iloc[2], abs=1e-12)


def test_icc_intervals_match_shrout_fleiss_1979() -> None:
    """Shrout & Fleiss (1979) give 95 % intervals for their Table 2 example: ICC(2,1) .29 in
    (.019, .761) and ICC(3,1) .71 in (.342, .946)."""
    low, up = ag.icc_a1_ci(SF_TABLE)
    assert (round(low, 2), round(up, 2)) == (0.02, 0.76)
    low, up = ag.icc_c1_ci(SF_TABLE)
    assert (round(low, 2), round(up, 2)) == (0.34, 0.95)


@pytest.mark.filterwarnings("ignore::DeprecationWarning", "ignore::FutureWarning")
def test_icc_intervals_match_pingouin() -> None:
    """pingouin's CI95% (rounded there to 2 decimals) on Shrout & Fleiss, all sample raters, one blendshape."""
    import pandas as pd
    import pingouin as pg

    cube, *_ = ag.ratings_cube(read_ratings(RATINGS))
    for x in (SF_TABLE, cube.reshape(-1, cube.shape[2]), cube[:, 1, :]):
        n, k = x.shape
        long = pd.DataFrame({"target": np.repeat(np.arange(n), k), "rater": np.tile(np.arange(k), n),
                             "rating": x.ravel()})
        table = pg.intraclass_corr(long, targets="target", raters="rater", ratings="rating")
        ci = table[[c for c in table.columns if c.startswith("CI")][0]]
        np.testing.assert_allclose(ag.icc_a1_ci(x), ci.iloc[1], atol=0.0051)
        np.testing.assert_allclose(ag.icc_c1_ci(x), ci.iloc[2], atol=0.0051)


def test_icc_intervals_are_wide_with_18_poses_and_in_the_report() -> None:
    """The sample lab's blind round (18 poses): each blendshape's interval contains its ICC and spans
    more than 0.1; the report prints them."""
    report = ag.agreement_report(read_ratings(RATINGS))
    for s in report.per_blendshape:
        assert s.icc_a1_ci[0] < s.icc_a1 < s.icc_a1_ci[1] and s.icc_a1_ci[1] - s.icc_a1_ci[0] > 0.1
        assert s.icc_c1_ci[0] < s.icc_c1 < s.icc_c1_ci[1]
    text = ag.format_report(report)
    assert "95 % CI" in text and ag.format_ci(report.overall.icc_a1_ci) in text


def _alpha_interval_by_hand(x: np.ndarray) -> float:
    """Krippendorff's alpha, interval metric, from its pairable-values definition (units x raters)."""
    units = [row[np.isfinite(row)] for row in x]
    units = [u for u in units if u.size >= 2]
    values = np.concatenate(units)
    n = values.size
    d_o = sum(sum((a - b) ** 2 for a, b in itertools.permutations(u, 2)) / (u.size - 1) for u in units) / n
    d_e = sum((a - b) ** 2 for a, b in itertools.permutations(values, 2)) / (n * (n - 1))
    return 1.0 - d_o / d_e


def test_alpha_matches_krippendorff_2011_and_a_hand_computation() -> None:
    nan = math.nan
    # Krippendorff (2011), "Computing Krippendorff's alpha-reliability", the example with missing data
    example = np.array([[1, 2, 3, 3, 2, 1, 4, 1, 2, nan, nan, nan], [1, 2, 3, 3, 2, 2, 4, 1, 2, 5, nan, 3],
                        [nan, 3, 3, 3, 2, 3, 4, 2, 2, 5, 1, nan], [1, 2, 3, 3, 2, 4, 4, 1, 2, 5, 1, nan]]).T
    assert round(ag.krippendorff_alpha_interval(example), 3) == 0.849
    assert _alpha_interval_by_hand(example) == pytest.approx(ag.krippendorff_alpha_interval(example), abs=1e-9)
    cube, *_ = ag.ratings_cube(read_ratings(RATINGS))
    x = cube.reshape(-1, cube.shape[2])
    assert _alpha_interval_by_hand(x) == pytest.approx(ag.krippendorff_alpha_interval(x), abs=1e-9)


def test_bland_altman_bias_and_limits() -> None:
    a = np.array([0.1, 0.5, 0.9, 0.3, np.nan])
    b = np.array([0.2, 0.4, 0.7, 0.3, 0.5])
    ba = ag.bland_altman(a, b, "R1", "R2")
    d = np.array([-0.1, 0.1, 0.2, 0.0])
    assert ba.n == 4 and ba.bias == pytest.approx(d.mean())
    assert ba.loa_high == pytest.approx(d.mean() + 1.96 * d.std(ddof=1))
    assert ba.loa_low == pytest.approx(d.mean() - 1.96 * d.std(ddof=1))
    with pytest.raises(ValueError, match="at least 2 paired ratings, found 1"):
        ag.bland_altman([0.1, np.nan], [0.2, 0.3])


def test_report_on_the_sample_raters() -> None:
    ratings = read_ratings(RATINGS)
    report = ag.agreement_report(ratings, flag_pct=12.5)
    assert report.raters == ["R1", "R2", "R3"] and len(report.poses) == 18
    assert report.overall.disagreement_pct == pytest.approx(mean_abs_disagreement_pct(ratings))
    assert 8.0 < report.overall.disagreement_pct < 14.0  # the paper: 11 %
    for s in report.per_blendshape:
        assert s.disagreement_pct == pytest.approx(
            mean_abs_disagreement_pct([r for r in ratings if r.blendshape == s.name]))
    assert report.flagged == [p for p, pct in report.per_pose_pct.items() if pct > 12.5]
    assert report.flagged and len(report.flagged) < 18
    assert [(p.rater_a, p.rater_b) for p in report.pairs] == [("R1", "R2"), ("R1", "R3"), ("R2", "R3")]
    text = ag.format_report(report)
    for needle in ("ICC(A,1)", "ICC(C,1)", "alpha", "Bland-Altman", *report.flagged):
        assert needle in text


def test_a_missing_rating_is_listed_and_left_out_of_the_iccs() -> None:
    ratings = [r for r in read_ratings(RATINGS) if not (r.pose_id == "pose05" and r.rater == "R2"
                                                        and r.blendshape == "mouth_open")]
    report = ag.agreement_report(ratings)
    assert report.incomplete == ["pose05"]
    mouth_open = next(s for s in report.per_blendshape if s.name == "mouth_open")
    cube, poses, names, raters = ag.ratings_cube(ratings)
    complete = np.delete(cube[:, names.index("mouth_open"), :], poses.index("pose05"), axis=0)
    assert mouth_open.icc_a1 == pytest.approx(ag.icc_a1(complete))
    assert np.isfinite(mouth_open.alpha)


@pytest.mark.parametrize(("match", "ratings"), [
    ("at least 2 raters and 2 poses, found 1 raters",
     [Rating("p1", "R1", "mouth_open", 0.1), Rating("p2", "R1", "mouth_open", 0.2)]),
    ("blendshape: expected one of .*found 'smile'", [Rating("p1", "R1", "smile", 0.1)]),
])
def test_bad_ratings_are_user_errors(match: str, ratings: list[Rating]) -> None:
    with pytest.raises(UserError, match=match):
        ag.agreement_report(ratings)


def test_ratings_from_keyframes_evaluate_each_raters_curve_at_the_pose_frames() -> None:
    session = SAMPLES / "P01_20260112-093000_cardio"
    poses = read_poses(SAMPLES / "reliability" / "poses.csv")
    ratings = ag.ratings_from_keyframes(session, poses)
    mine = [p for p in poses if p.session_id == session.name]
    assert len(ratings) == len(mine) * 3 * 4
    r1 = read_annotations(session / "annotations" / "R1.json")
    for r in ratings:
        if r.rater == "R1":
            frame = next(p.frame for p in mine if p.pose_id == r.pose_id)
            assert r.weight == pytest.approx(float(r1.tracks[r.blendshape].evaluate(frame)), abs=1e-4)


def test_gather_prefers_the_blind_round_then_key_frames() -> None:
    ratings, source = ag.gather_ratings(SAMPLES)
    assert ratings == read_ratings(RATINGS) and "blind round" in source
    ratings, source = ag.gather_ratings(SAMPLES / "P02_20260112-113700_strength")
    assert "key-frames" in source and {r.pose_id for r in ratings} == {"pose04", "pose05", "pose06"}


def test_proposed_poses_come_from_hr_and_phase_extremes() -> None:
    session = read_session(SAMPLES / "P03_20260113-094400_cardio")
    poses = ag.propose_poses(session, 18)
    assert len(poses) == 18
    t = np.array([p.t_s for p in poses])
    assert np.all(np.diff(t) >= 5.0 - 0.2)  # min gap, up to one frame of rounding
    hr = [(h.t_s, h.hr_bpm) for h in session.heart_rate if h.valid and h.hr_bpm]
    t_peak = max(hr, key=lambda x: x[1])[0]
    assert np.min(np.abs(t - t_peak)) < 0.2
    assert all(session.frame_times_s[p.frame] == p.t_s for p in poses)


def test_gather_proposes_poses_when_a_lab_has_no_reliability_folder(tmp_path: Path) -> None:
    import shutil

    for name in ("P01_20260112-093000_cardio", "P04_20260113-115100_strength"):
        dst = tmp_path / name
        dst.mkdir()
        for f in ("session.json", "heart_rate.csv", "events.csv", "video_frames.csv"):
            shutil.copy(SAMPLES / name / f, dst)
        shutil.copytree(SAMPLES / name / "annotations", dst / "annotations")
    ratings, source = ag.gather_ratings(tmp_path)
    report = ag.agreement_report(ratings, source=source)
    assert len(report.poses) == 18 and report.raters == ["R1", "R2", "R3"]
    assert "18 pose frames" in source


def test_bland_altman_png(tmp_path: Path) -> None:
    pytest.importorskip("matplotlib")
    report = ag.agreement_report(read_ratings(RATINGS))
    out = ag.save_bland_altman_png(report, tmp_path / "ba.png")
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and out.stat().st_size > 5000
    with pytest.raises(FileExistsError):
        ag.save_bland_altman_png(report, out)


def test_keys_accepted_from_the_machine_stay_out_of_the_ratings_and_the_human_mean(tmp_path: Path) -> None:
    import shutil

    from effortface.annotate.annotate_session import AnnotateSession
    from tests.annotate.machine_helpers import write_fake_machine

    session = tmp_path / "P01_20260112-093000_cardio"
    shutil.copytree(SAMPLES / session.name, session, ignore=shutil.ignore_patterns("serial"))
    write_fake_machine(session, no_face=False)
    poses = read_poses(SAMPLES / "reliability" / "poses.csv")
    mine = [p for p in poses if p.session_id == session.name]
    s = AnnotateSession(session, "R4")  # R4 accepts the machine on every blendshape, edits one key
    try:
        for name in s.blendshape_names:
            s.set_blendshape(name)
            s.accept_machine(0, s.n_frames - 1)
        s.set_blendshape("eye_squint")
        edited = min((k.frame for k in s.track.keys), key=lambda f: abs(f - mine[0].frame))  # near a pose
        s.set_key(0.4, edited)
    finally:
        s.close()
    ratings = ag.ratings_from_keyframes(session, poses)
    r4 = [r for r in ratings if r.rater == "R4"]
    ann = read_annotations(session / "annotations" / "R4.json")
    # only poses whose nearest key is the edited one: eye_squint near that frame, nothing else
    expected = [p.pose_id for p in mine if ann.tracks["eye_squint"].origins([p.frame])[0] == "edited"]
    assert mine[0].pose_id in expected
    assert sorted(r.pose_id for r in r4) == sorted(expected) and {r.blendshape for r in r4} == {"eye_squint"}
    assert len([r for r in ratings if r.rater == "R1"]) == len(mine) * 4  # the typed raters untouched
    _, source = ag.gather_ratings(session)
    counts = ag.origin_seconds_by_rater([session])
    assert counts["R1"]["machine"] == counts["R1"]["edited"] == 0 and counts["R1"]["typed"] > 4 * 600
    assert counts["R4"]["typed"] == 0 and 0 < counts["R4"]["edited"] < 20 and counts["R4"]["machine"] > 4 * 600
    assert f"R4 machine {counts['R4']['machine']} s, edited {counts['R4']['edited']} s (machine: left out)" in source
