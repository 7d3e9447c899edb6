"""Fixtures the Annotate stage's GUI tests share (test_annotate_gui.py, test_annotate_daily.py)."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SAMPLES = ROOT / "sample_sessions"
#: the sample session the stage tests annotate
SESSION = "P01_20260112-093000_cardio"


@pytest.fixture
def lab(tmp_path: Path) -> Path:
    """A copy of one sample session (with the three sample raters' files) and the reliability round."""
    dst = tmp_path / "lab"
    shutil.copytree(SAMPLES / SESSION, dst / SESSION, ignore=shutil.ignore_patterns("serial", "work.csv"))
    shutil.copytree(SAMPLES / "reliability", dst / "reliability")
    return dst


@pytest.fixture
def stage(request: pytest.FixtureRequest, qtbot, lab: Path):
    """The Annotate stage on :func:`lab`, shown at the test module's ``STAGE_SIZE`` (default 1400x900)."""
    from effortface.annotate.gui.annotate_stage import QtAnnotateStage

    widget = QtAnnotateStage(lab, cache_frames=64)
    qtbot.addWidget(widget)
    widget.resize(*getattr(request.module, "STAGE_SIZE", (1400, 900)))
    widget.show()
    qtbot.waitExposed(widget)
    yield widget
    widget.shutdown()
