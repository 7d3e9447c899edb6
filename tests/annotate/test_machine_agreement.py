"""The machine rater in ``effortface agreement``: apart from the humans, against each and their mean, with CIs."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from effortface.annotate.agreement import (HUMAN_MEAN, MACHINE_RATER, agreement_report, alpha_interval_pairs,
                                           format_report, gather_poses, gather_ratings, krippendorff_alpha_interval,
                                           machine_ratings, machine_report, machine_stats)
from effortface.annotate.machine.track import read_machine_track
from effortface.cli import main
from tests.annotate.machine_helpers import write_fake_machine

ROOT = Path(__file__).resolve().parents[2]
SAMPLES = ROOT / "sample_sessions"


@pytest.fixture(scope="module")
def lab(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A copy of the sample lab (without videos) whose sessions carry a machine track."""
    out = tmp_path_factory.mktemp("lab") / "lab"
    shutil.copytree(SAMPLES, out, ignore=shutil.ignore_patterns("*.avi", "_ground_truth", "serial"))
    for s in sorted(out.glob("P0*")):
        write_fake_machine(s)
    return out


def test_closed_form_alpha_equals_the_krippendorff_package() -> None:
    rng = np.random.default_rng(3)
    a = rng.uniform(0, 1, 30)
    b = np.clip(a + rng.normal(0, 0.2, 30), 0, 1)
    assert alpha_interval_pairs(a, b) == pytest.approx(krippendorff_alpha_interval(np.column_stack([a, b])), abs=1e-9)


def test_a_perfect_machine_scores_one_and_a_noisy_one_less_with_seeded_cis() -> None:
    rng = np.random.default_rng(0)
    ref = rng.uniform(0, 1, (18, 4))
    perfect = machine_stats(ref.copy(), ref, reference_name="R1", names=["a", "b", "c", "d"], n_boot=200)
    assert [s.name for s in perfect] == ["a", "b", "c", "d", "all"]
    assert all(s.icc_a1 == pytest.approx(1) and s.mad_pct == 0 for s in perfect)
    noisy = np.clip(ref + rng.normal(0, 0.25, ref.shape), 0, 1)
    first = machine_stats(noisy, ref, reference_name="R1", names=["a", "b", "c", "d"], n_boot=200, seed=7)
    again = machine_stats(noisy, ref, reference_name="R1", names=["a", "b", "c", "d"], n_boot=200, seed=7)
    assert first == again
    pooled = first[-1]
    assert pooled.n_items == 72 and pooled.icc_a1 < 0.9 and pooled.mad_pct > 10
    for value, (low, high) in ((pooled.icc_a1, pooled.icc_a1_ci), (pooled.alpha, pooled.alpha_ci),
                               (pooled.mad_pct, pooled.mad_pct_ci)):
        assert low < value < high


def test_machine_values_are_the_track_at_the_nearest_frame(lab: Path) -> None:
    poses = gather_poses(lab)
    ratings, no_face = machine_ratings(lab, poses)
    assert ratings and all(r.rater == MACHINE_RATER for r in ratings)
    pose = next(p for p in poses if p.pose_id not in no_face)
    track = read_machine_track(lab / pose.session_id)
    i = int(np.argmin(np.abs(track.t_s - (pose.t_s + 0.01))))
    got = {r.blendshape: r.weight for r in ratings if r.pose_id == pose.pose_id}
    assert got["mouth_open"] == pytest.approx(track.weights[i, 1], abs=1e-4)
    for pid in no_face:  # a pose on a no-face frame gets no machine rating
        p = next(p for p in poses if p.pose_id == pid)
        t = read_machine_track(lab / p.session_id)
        assert not t.face[int(np.argmin(np.abs(t.t_s - p.t_s)))]
        assert not [r for r in ratings if r.pose_id == pid]


def test_cli_prints_the_humans_report_unchanged_then_the_machine_apart(lab: Path,
                                                                       capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["agreement", str(lab)]) == 0
    out = capsys.readouterr().out
    ratings, source = gather_ratings(lab)
    human = format_report(agreement_report(ratings, source=source))
    assert out.startswith(human)
    section = out[len(human):]
    assert "Machine rater (MediaPipe face landmarker): apart from the humans" in section
    assert MACHINE_RATER not in human.splitlines()[1]  # not among the raters
    for ref in ("R1", "R2", "R3", HUMAN_MEAN):
        assert [line for line in section.splitlines() if line.strip().startswith(f"{ref} ") and " all " in line]
    expected = machine_report(ratings, machine_ratings(lab, gather_poses(lab))[0])
    mean_all = next(s for s in expected.stats if s.reference == HUMAN_MEAN and s.name == "all")
    assert f"{mean_all.icc_a1:9.3f}" in section
    assert mean_all.icc_a1 > 0.8  # the machine is the raters' mean plus noise


def test_machine_in_mean_counts_it_among_the_raters(lab: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["agreement", str(lab), "--machine-in-mean"]) == 0
    out = capsys.readouterr().out
    assert out.splitlines()[1].startswith(f"raters: R1, R2, R3, {MACHINE_RATER}")
    assert "(also counted as a rater above (--machine-in-mean))" in out


def test_no_machine_track_leaves_the_report_as_before(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["agreement", str(SAMPLES)]) == 0
    out = capsys.readouterr().out
    ratings, source = gather_ratings(SAMPLES)
    assert out == format_report(agreement_report(ratings, source=source))
