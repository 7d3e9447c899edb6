"""Every figure the guide states about the shipped sample lab is what the shipped lab gives (issue 40).

Each entry of :data:`FIGURES` is a sentence of a page, as a regular expression whose named groups are
the figures; :func:`lab_figures` computes them from ``sample_sessions/`` through the product's own
code (the agreement report of ``effortface agreement``, the session folder reader, the first-use
build estimate the product prints), formatted as the product prints them. A figure that drifts
(the lab regenerated, a statistic changed) fails here, naming the page, the figure and both values.
Figures that cannot be computed cheaply (training scores, timings) are stated in the guide as
measured, with their date or circumstances, and are not checked here.
"""

from __future__ import annotations

import csv
import json
import re
from functools import cache
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import ROOT

LAB = ROOT / "sample_sessions"
DOCS = ROOT / "docs"

#: (page under docs/, a sentence with the figures as named groups)
FIGURES = [
    ("guide/annotate.md", r"the sample lab's blind round gives (?P<diff_all>[\d.]+) %"),
    ("guide/annotate.md", r"the sample lab's blind round: overall ICC\(A,1\) (?P<icc_all>[\d.]+) (?P<icc_all_ci>\[[\d., ]+\]);"
                          r"\s+mouth_open\s+(?P<icc_mouth_open>[\d.]+) (?P<icc_mouth_open_ci>\[[\d., ]+\])"),
    ("guide/annotate.md", r"With (?P<poses>\d+)\s+poses they are wide"),
    ("guide/scores-and-live-streams.md", r"on the sample lab's blind round \((?P<poses>\d+) poses\), ICC\(A,1\)\s+"
                                         r"(?P<icc_all_ci>\[[\d., ]+\]) where\s+the F-based interval is "
                                         r"(?P<icc_all_f_ci>\[[\d., ]+\])"),
    ("guide/sample-data.md", r"\((?P<participants>\d+) participants, each with a cardio and a strength\s+session of "
                             r"(?P<minutes>\d+-\d+) minutes: (?P<sessions>\d+) sessions, (?P<size_mb>\d+) MB, .*?"
                             r"face video at (?P<video_fps>[\d.]+) fps,.*?(?P<raters>\d+) raters' key-frames and a blind\s+"
                             r"reliability round of (?P<poses>\d+) poses;"),
    ("guide/getting-started.md", r"in about (?P<build_estimate_s>\d+) s \(the estimate its line prints"),
    ("guide/troubleshooting.md", r"its estimate, about (?P<build_estimate_s>\d+) s, once"),
    ("guide/tutorial-record.md", r"The lab holds (?P<sessions>\d+) sessions of (?P<participants>\d+) participants"),
    ("guide/tutorial-train.md", r"`\./sample_sessions`: (?P<sessions>\d+) sessions of (?P<participants>\d+) participants"),
    ("guide/tutorial-key.md", r"the lab's `reliability/poses\.csv`: (?P<poses>\d+)\s+frames"),
    ("guide/reliability.md", r"\| 160 x 120, (?P<video_fps>[\d.]+) fps \(the sample lab\)"),
    ("guide/machine-rater-effort-mapping.md", r"the sample lab's (?P<video_fps>[\d.]+) frames/s"),
]


def _sessions() -> list[Path]:
    return sorted(p.parent for p in LAB.glob("*/session.json"))


def _agreement() -> dict[str, str]:
    """The blind round's figures, as ``effortface agreement sample_sessions`` prints them."""
    from effortface.annotate.agreement import (agreement_report, format_ci, gather_ratings, icc_a1_ci,
                                               ratings_cube)

    ratings, _source = gather_ratings(LAB)
    report = agreement_report(ratings)
    mouth_open = next(s for s in report.per_blendshape if s.name == "mouth_open")
    cube = ratings_cube(ratings)[0]
    return {"diff_all": f"{report.overall.disagreement_pct:.1f}", "icc_all": f"{report.overall.icc_a1:.3f}",
            "icc_all_ci": format_ci(report.overall.icc_a1_ci),
            "icc_all_f_ci": format_ci(icc_a1_ci(cube.reshape(-1, cube.shape[2]))),
            "icc_mouth_open": f"{mouth_open.icc_a1:.3f}", "icc_mouth_open_ci": format_ci(mouth_open.icc_a1_ci),
            "poses": str(len(report.poses)), "raters": str(len(report.raters))}


def _video_fps(session: Path) -> float:
    with open(session / "video_frames.csv", newline="") as f:
        t_s = np.array([float(row["t_s"]) for row in csv.DictReader(f)])
    return float(1 / np.median(np.diff(t_s)))


@cache
def lab_figures() -> dict[str, str]:
    """The figures of the shipped lab, formatted as the guide states them."""
    from effortface.samplelab import BUILD_ESTIMATE_S

    sessions = _sessions()
    minutes = []
    for s in sessions:
        with open(s / "heart_rate.csv", newline="") as f:
            minutes.append(float(list(csv.DictReader(f))[-1]["t_s"]) / 60)
    size = sum(f.stat().st_size for s in [*sessions, LAB / "reliability"] for f in s.rglob("*") if f.is_file())
    size += (LAB / "participants.tsv").stat().st_size
    fps = {round(_video_fps(s), 1) for s in sessions}
    assert len(fps) == 1, fps
    participants = {json.loads((s / "session.json").read_text())["participant"]["code"] for s in sessions}
    return {**_agreement(), "participants": str(len(participants)), "sessions": str(len(sessions)),
            "minutes": f"{int(min(minutes))}-{int(np.ceil(max(minutes)))}", "size_mb": f"{size / 1e6:.0f}",
            "video_fps": f"{fps.pop():g}", "build_estimate_s": str(BUILD_ESTIMATE_S)}


@pytest.mark.parametrize(("page", "pattern"), FIGURES, ids=[f"{p}:{i}" for i, (p, _) in enumerate(FIGURES)])
def test_the_guide_states_the_shipped_labs_figures(page: str, pattern: str) -> None:
    text = (DOCS / page).read_text(encoding="utf-8")
    found = re.search(pattern, text, re.S)
    assert found, f"docs/{page}: expected a sentence matching {pattern!r}, found none (reworded? update FIGURES)"
    expected = lab_figures()
    wrong = {k: (v, expected[k]) for k, v in found.groupdict().items() if v != expected[k]}
    assert not wrong, f"docs/{page}: figures (page, shipped lab): {wrong}"


def test_the_figures_are_the_products() -> None:
    """The check can fail: the agreement figures are those ``effortface agreement`` prints."""
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-m", "effortface", "agreement", str(LAB)], capture_output=True,
                          text=True, cwd=ROOT, timeout=300)
    assert done.returncode == 0, done.stderr
    f = lab_figures()
    row = re.search(r"^  all\s+72\s+(\S+)\s+\[[^\]]+\]\s+(\S+)\s+(\[[^\]]+\])", done.stdout, re.M)
    assert row and row.groups() == (f["diff_all"], f["icc_all"], f["icc_all_ci"]), done.stdout[:3000]


#: a sentence about the sample lab with such a figure is one this test checks or one stated as measured
FIGURE = re.compile(r"\d\.\d|\d %|\d s\b|\d MB")
LAB_WORDS = re.compile(r"sample lab|sample_sessions", re.I)
MEASURED = re.compile(r"measured|earlier|of the time|before|bench", re.I)


def _flat(text: str) -> str:
    """A page as one line: code blocks left out, paragraphs and headings apart (`` ¶ ``), spaces single."""
    text = re.sub(r"^```.*?^```", "", text, flags=re.M | re.S)
    return " ".join(re.sub(r"\n\s*\n|\n(?=#)", " \u00b6 ", text).split())


def _sentences(flat: str) -> list[tuple[int, int, str]]:
    """(start, end, sentence) of a flattened page."""
    out, start = [], 0
    for m in re.finditer(r"(?<=[.;:])\s+(?=[A-Z(`*|-])|\s(?=\| )|\s\u00b6\s", flat):
        out.append((start, m.start(), flat[start:m.start()]))
        start = m.end()
    out.append((start, len(flat), flat[start:]))
    return out


def test_every_figure_of_the_sample_lab_is_checked_or_dated() -> None:
    """No figure about the shipped lab escapes: in every guide page, a sentence that names the sample
    lab and states a figure is either one of :data:`FIGURES` (checked above) or says it was measured
    (when, or on which earlier lab)."""
    loose = []
    for page in sorted((DOCS / "guide").glob("*.md")):
        flat = _flat(page.read_text(encoding="utf-8"))
        rel = page.relative_to(DOCS).as_posix()
        checked = [m.span() for p, pattern in FIGURES if p == rel for m in re.finditer(pattern, flat, re.S)]
        for start, end, sentence in _sentences(flat):
            if not (LAB_WORDS.search(sentence) and FIGURE.search(sentence)) or MEASURED.search(sentence):
                continue
            if not any(a < end and start < b for a, b in checked):
                loose.append(f"docs/{rel}: {sentence[:160]}")
    assert not loose, "figures of the sample lab neither checked nor dated:\n" + "\n".join(loose)
