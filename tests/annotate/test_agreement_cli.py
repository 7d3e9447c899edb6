"""``effortface agreement``: the same report as the library, one-line errors with exit status 2."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from effortface.annotate.agreement import agreement_report, format_report, gather_ratings
from effortface.annotate.reliability import read_ratings
from effortface.cli import main

ROOT = Path(__file__).resolve().parents[2]
SAMPLES = ROOT / "sample_sessions"
RATINGS = SAMPLES / "reliability" / "ratings.csv"


def test_cli_prints_the_library_report_for_the_sample_raters() -> None:
    done = subprocess.run([sys.executable, "-m", "effortface", "agreement", "--ratings", str(RATINGS)],
                          capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert done.returncode == 0, done.stderr
    expected = format_report(agreement_report(read_ratings(RATINGS), source=str(RATINGS)))
    assert done.stdout == expected
    assert "pose13" in done.stdout.split("Flagged poses")[1]  # 16.3 % > 15 %


def test_dir_and_ratings_give_the_same_statistics(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["agreement", str(SAMPLES)]) == 0
    by_dir = capsys.readouterr().out
    assert main(["agreement", "--ratings", str(RATINGS)]) == 0
    by_csv = capsys.readouterr().out
    assert by_dir.splitlines()[1:] == by_csv.splitlines()[1:]  # only the source line differs


def test_session_report_uses_the_raters_key_frames(capsys: pytest.CaptureFixture[str]) -> None:
    session = SAMPLES / "P05_20260114-095800_cardio"
    assert main(["agreement", str(session), "--threshold", "5"]) == 0
    out = capsys.readouterr().out
    ratings, source = gather_ratings(session)
    assert out == format_report(agreement_report(ratings, flag_pct=5.0, source=source))


def test_plot_option_writes_a_png_and_never_overwrites(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    pytest.importorskip("matplotlib")
    png = tmp_path / "ba.png"
    assert main(["agreement", "--ratings", str(RATINGS), "--plot", str(png)]) == 0
    assert png.read_bytes()[:4] == b"\x89PNG"
    assert main(["agreement", "--ratings", str(RATINGS), "--plot", str(png)]) == 2
    assert "--plot" in capsys.readouterr().err


def _bad_ratings(tmp_path: Path) -> str:
    p = tmp_path / "bad.csv"
    p.write_text("pose_id,rater,blendshape,weight\np1,R1,mouth_open,1.7\n")
    return str(p)


def _one_rater(tmp_path: Path) -> str:
    p = tmp_path / "one.csv"
    p.write_text("pose_id,rater,blendshape,weight\np1,R1,mouth_open,0.1\np2,R1,mouth_open,0.3\n")
    return str(p)


@pytest.mark.parametrize(("message", "argv"), [
    (r"expected exactly one of SESSION\|DIR or --ratings CSV, found neither", lambda t: []),
    (r"expected exactly one of SESSION\|DIR or --ratings CSV, found both", lambda t: [str(SAMPLES), "--ratings", str(RATINGS)]),
    (r"--ratings .*nope.csv: expected a CSV file, found nothing", lambda t: ["--ratings", str(t / "nope.csv")]),
    (r"bad.csv:2: expected a weight in \[0, 1\], found '1.7'", lambda t: ["--ratings", _bad_ratings(t)]),
    (r"expected at least 2 raters and 2 poses, found 1 raters", lambda t: ["--ratings", _one_rater(t)]),
    (r"expected a session folder or a folder of sessions, found nothing", lambda t: [str(t / "missing")]),
    (r"expected a session folder or a folder of sessions, found neither", lambda t: [str(t)]),
    (r"--threshold: expected a percentage from 0 to 100, found 150", lambda t: ["--ratings", str(RATINGS), "--threshold", "150"]),
])
def test_bad_input_is_one_line_and_status_2(message: str, argv, tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["agreement", *argv(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1
    assert re.search(message, err), err


def _write(tmp_path: Path, name: str, rows: str) -> str:
    p = tmp_path / name
    p.write_text("pose_id,rater,blendshape,weight\n" + rows)
    return str(p)


@pytest.mark.parametrize(("message", "rows"), [
    # no pose rated by two raters (was a ValueError traceback from mean_abs_disagreement_pct)
    (r"ratings \(.*noverlap.csv\): expected at least one pose and blendshape rated by two raters, found none",
     "p1,R1,mouth_open,0.5\np2,R2,mouth_open,0.6\n"),
    # R3 shares a single rating with R1 and R2: no Bland-Altman for those pairs (was a ValueError)
    (r"expected raters R1 and R3 to rate at least 2 pose blendshapes in common \(for Bland-Altman\), found 1",
     ("p1,R1,mouth_open,0.5\np1,R2,mouth_open,0.6\np2,R1,mouth_open,0.2\np2,R2,mouth_open,0.3\n"
      "p2,R3,mouth_open,0.4\n")),
])
def test_ratings_without_overlap_are_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                              message: str, rows: str) -> None:
    assert main(["agreement", "--ratings", _write(tmp_path, "noverlap.csv", rows)]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert re.search(message, err), err


def test_a_blendshape_no_two_raters_share_is_reported_as_nan(tmp_path: Path,
                                                             capsys: pytest.CaptureFixture[str]) -> None:
    """Only one rater rated eye_squint: its row is NaN, the rest of the report is computed."""
    rows = ("p1,R1,mouth_open,0.5\np1,R2,mouth_open,0.6\np2,R1,mouth_open,0.2\np2,R2,mouth_open,0.4\n"
            "p1,R1,eye_squint,0.3\n")
    assert main(["agreement", "--ratings", _write(tmp_path, "partial.csv", rows)]) == 0
    out = capsys.readouterr().out
    # diff % and its interval, ICC(A,1), ICC(C,1) and alpha with theirs: all NaN
    assert re.search(r"eye_squint\s+2\s+nan\s+\[nan, nan\]\s+nan\s+\[nan, nan\]\s+nan\s+\[nan, nan\]"
                     r"\s+nan\s+\[nan, nan\]", out), out
    assert re.search(r"mouth_open\s+2\s+15\.0", out), out


@pytest.mark.parametrize(("message", "plot"), [
    (r"--plot .*p\.txt: expected a path ending in \.png, found '\.txt'", lambda t: t / "p.txt"),
    (r"--plot .*nonexistent/x\.png: expected an existing folder for the PNG, found nothing at '.*nonexistent'",
     lambda t: t / "nonexistent" / "x.png"),
    (r"--plot .*afile/x\.png: expected an existing folder for the PNG, found a file at '.*afile'",
     lambda t: t / "afile" / "x.png"),
    (r"--plot .*dir\.png: expected a new PNG file, found a folder", lambda t: t / "dir.png"),
    (r"--plot /proc/x\.png: expected a writable PNG path, found ", lambda t: Path("/proc/x.png")),
])
def test_bad_plot_paths_are_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str], message: str, plot) -> None:
    pytest.importorskip("matplotlib")
    (tmp_path / "afile").write_text("keep")
    (tmp_path / "dir.png").mkdir()
    target = plot(tmp_path)
    assert main(["agreement", str(SAMPLES), "--plot", str(target)]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert re.search(message, err), err
    assert (tmp_path / "afile").read_text() == "keep" and not list((tmp_path / "dir.png").iterdir())
    assert not (tmp_path / "p.txt").exists()


def test_a_lab_with_a_machine_track_gets_the_one_line_machine_summary(tmp_path: Path,
                                                                      capsys: pytest.CaptureFixture[str]) -> None:
    """The machine against the human mean, pooled over blendshapes, in one line (as the app's report shows it)."""
    import shutil

    from effortface.annotate.agreement import HUMAN_MEAN, gather_poses, machine_ratings, machine_report
    from tests.annotate.machine_helpers import write_fake_machine

    lab = tmp_path / "lab"
    shutil.copytree(SAMPLES, lab, ignore=shutil.ignore_patterns("*.avi", "_ground_truth", "serial"))
    for session in sorted(lab.glob("P0*")):
        write_fake_machine(session)
    assert main(["agreement", str(lab)]) == 0
    out = capsys.readouterr().out
    lines = [line for line in out.splitlines() if line.startswith("Machine against the human mean")]
    assert len(lines) == 1, out
    ratings, _ = gather_ratings(lab)
    pooled = next(s for s in machine_report(ratings, machine_ratings(lab, gather_poses(lab))[0]).stats
                  if s.reference == HUMAN_MEAN and s.name == "all")
    match = re.fullmatch(r"Machine against the human mean, all blendshapes: n (\d+), ICC\(A,1\) ([-\d.]+) "
                         r"\[([-\d.]+), ([-\d.]+)\], alpha ([-\d.]+), MAD ([\d.]+) % of the range", lines[0])
    assert match, lines[0]
    n, icc, lo, hi, alpha, mad = match.groups()
    assert int(n) == pooled.n_items > 0
    assert float(icc) == pytest.approx(pooled.icc_a1, abs=0.005) and float(lo) <= float(icc) <= float(hi)
    assert float(alpha) == pytest.approx(pooled.alpha, abs=0.005)
    assert float(mad) == pytest.approx(pooled.mad_pct, abs=0.05) and float(icc) > 0.8  # the raters' mean + noise
    # the summary sits in the machine's section, after the humans' report (which stays unchanged)
    assert out.index("apart from the humans") < out.index(lines[0])


def test_no_machine_track_no_machine_summary(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["agreement", str(SAMPLES)]) == 0
    assert "Machine against the human mean" not in capsys.readouterr().out
