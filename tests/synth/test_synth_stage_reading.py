"""Issue 34: the Synthesize stage reads a clip with a unit and an up axis chosen beside Mapping...,
shows the plausibility gate's refusal in its status line, and trusts a skeleton on request."""

from __future__ import annotations

import json
from pathlib import Path

from effortface.synth.gui.synth_stage import QtSynthStage
from effortface.synth.synth_session import SynthSession
from tests.synth.bvh_fixtures import bandai_layout_bvh


def test_a_child_is_refused_in_the_status_line_then_trusted(qtbot, tmp_path: Path) -> None:
    stage = QtSynthStage(SynthSession(), motion_dir=tmp_path)
    qtbot.addWidget(stage)
    clip = bandai_layout_bvh(tmp_path / "child.bvh", scale=0.7)
    assert stage.set_reading(unit_m=0.01)
    assert stage.unit_combo.currentText() == "cm"
    assert not stage.load_clip(clip)
    assert stage.status.text().startswith(f"{clip}: standing height 1.11 m: expected 1.2-2.2 m; check --unit-m")
    assert "b00020" in stage.status.styleSheet()  # in red
    assert stage.session.motion is None
    assert stage.set_reading(unit_m=0.01, trust_skeleton=True)
    assert stage.load_clip(clip) and stage.session.motion is not None and stage.trust_check.isChecked()
    out = stage.session.export(tmp_path / "child.csv")
    reading = json.loads(out.with_name("child.units.json").read_text())["reading"]
    assert reading["unit_m"] == 0.01 and reading["body"]["trusted"]


def test_an_up_axis_that_lays_the_body_down_is_refused_and_the_old_one_kept(qtbot, tmp_path: Path) -> None:
    stage = QtSynthStage(SynthSession(), motion_dir=tmp_path)
    qtbot.addWidget(stage)
    assert stage.load_clip(bandai_layout_bvh(tmp_path / "walk.bvh"))
    assert stage.session.reading["up_axis"] == "y"
    assert not stage.set_reading(up="z")
    assert "walk.bvh: standing height 0." in stage.status.text()
    assert stage.session.read.up is None and stage.up_combo.currentText() == "up: file"
    assert stage.set_reading(up="y") and stage.up_combo.currentText() == "up y"
    assert stage.session.reading["up_from"] == "given (--up)"
