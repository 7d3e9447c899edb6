"""The Synthesize stage's File info panel offscreen: the same report as ``effortface motion inspect``,
for a clip the conventions cannot map, after a partial mapping, and for a C3D (issue 34)."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from effortface.synth.gui.synth_stage import QtSynthStage
from effortface.synth.inspect import inspect_motion
from effortface.synth.read_options import MotionReadOptions
from effortface.synth.synth_session import SynthSession

DATA = Path(__file__).resolve().parents[1] / "data"
WALK = DATA / "bvh" / "bvhtoolbox_walk01.bvh"
PIG = DATA / "c3d" / "PiG_Calibration-FlatFoot-Full.c3d"
#: where the screenshot goes (the guide's copy is made by hand after looking at it)
SCREENSHOT = Path(os.environ.get("EFFORTFACE_FILEINFO_SCREENSHOT", "/tmp/synth_fileinfo_1280x800.png"))
pytestmark = pytest.mark.qt_log_ignore("This plugin does not support propagateSizeHints")


@pytest.fixture
def stage(qtbot) -> QtSynthStage:
    view = QtSynthStage(SynthSession(background=True), motion_dir=DATA / "bvh")
    qtbot.addWidget(view)
    view.resize(1280, 800)
    view.show()
    yield view
    view.shutdown()


def test_file_info_shows_the_inspection_and_follows_the_mapping(qtbot, stage: QtSynthStage, tmp_path: Path) -> None:
    assert stage.load_clip(WALK)
    stage.session.wait(30)
    assert "unmapped segments: left_foot, right_foot" in stage.status.text()  # no curves yet
    text = stage.show_file_info()
    assert text.splitlines() == inspect_motion(WALK).lines()  # the same report as the command
    assert "mapping     CMU (partial: 12 of 14 segments)" in text and "unmapped   left_foot, right_foot" in text
    feet = tmp_path / "feet.json"
    feet.write_text(json.dumps({"version": 2, "left_foot": ["LeftFoot", "LeftFoot_end"],
                                "right_foot": ["RightFoot", "RightFoot_end"]}))
    assert stage.set_mapping(feet)
    stage.session.wait(30)
    text = stage.file_info.toPlainText()
    assert text.splitlines() == inspect_motion(WALK, MotionReadOptions(mapping=str(feet))).lines()
    assert "mapping     user + CMU" in text and "  left_foot       LeftFoot -> LeftFoot_end" in text
    assert "unmapped   none" in text
    stage.bottom_tabs.setCurrentIndex(0)  # back to the curves, which now exist
    assert "w_per_kg" in stage.plots.curves
    stage.show_file_info()
    qtbot.wait(50)
    SCREENSHOT.parent.mkdir(parents=True, exist_ok=True)
    assert stage.grab().save(str(SCREENSHOT))
    # readable: the longest report line fits the panel's width without scrolling at 1280 x 800
    metrics = stage.file_info.fontMetrics()
    widest = max(metrics.horizontalAdvance(line) for line in text.splitlines())
    assert widest < stage.file_info.viewport().width(), (widest, stage.file_info.viewport().width())


def test_file_info_of_a_c3d_names_producer_and_markers(qtbot, stage: QtSynthStage) -> None:
    assert stage.load_clip(PIG)
    stage.session.wait(30)
    text = stage.show_file_info()
    assert "producer    Vicon Vicon Nexus" in text and "marker set  plug-in-gait" in text
    assert "LASI" in text and "mapping     CMU" in text
