"""The Capture stage offers Bluetooth LE straps beside serial ones and imports heart-rate files
(issue 35), the real main window offscreen (pytest-qt) on a copy of sample_sessions/."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from effortface.capture_tool.participants import REGISTRY_TSV, read_registry
from effortface.core.session.folder import read_session, validate_session

from .test_capture_gui import _fill_form
from .conftest import capture_stage_on
from .test_participant_truth import copy_sample_lab

pytestmark = pytest.mark.qt_log_ignore("This plugin does not support propagateSizeHints")
DATA = Path(__file__).resolve().parents[1] / "data" / "hr"


@pytest.fixture
def stage(qtbot, tmp_path: Path):
    yield from capture_stage_on(qtbot, copy_sample_lab(tmp_path / "lab"), tmp_path / "settings.ini")


def test_ble_straps_beside_serial_ones(qtbot, stage):
    pre = stage.preflight
    qtbot.waitUntil(lambda: pre.ble_status.text() != "scanning...", timeout=20_000)
    # this machine has no Bluetooth adapter: said in one line, no strap listed, nothing raised
    assert pre.ble_status.text().startswith(("no straps listed: ", "no heart-rate strap", "1 heart", "2 heart"))
    pre.port.setCurrentText("ble://C4:7C:8D:6A:1B:2E")
    assert pre.protocol.currentText() == "ble_hrm"
    assert pre.choice().port == "ble://C4:7C:8D:6A:1B:2E"


def test_import_heart_rate_action(qtbot, stage, tmp_path):
    lab = stage.session.out_dir
    _fill_form(stage, "P07")
    assert stage.import_heart_rate([str(DATA / "garmin-fenix5-run.fit"), str(DATA / "polar-s810-rr.hrm")])
    qtbot.waitUntil(lambda: stage.banner.text().startswith(("Imported", "Import refused")), timeout=30_000)
    assert stage.banner.text().startswith("Imported 2 session(s)"), stage.banner.text()
    folders = sorted(lab.glob("P07_*"))
    assert [f.name for f in folders] == ["P07_20080208-085032", "P07_20170611-143409"]
    for folder in folders:
        assert validate_session(folder) == []
    rr = read_session(folders[0]).heart_rate
    assert len(rr) == 4117 and all(len(r.rr_ms) == 1 for r in rr)
    assert read_registry(lab / REGISTRY_TSV)["P07"].mass_kg == pytest.approx(77.5)
    info = json.loads((folders[1] / "session.json").read_text())
    assert info["devices"]["heart_rate"]["device"] == "garmin fenix5"
    if os.environ.get("EFFORTFACE_SCREENSHOTS"):   # the report's look at it: the action under Record shown
        from PySide6 import QtWidgets

        stage.findChild(QtWidgets.QScrollArea).ensureWidgetVisible(stage.import_button)
        qtbot.wait(50)
        stage.window().grab().save(os.environ["EFFORTFACE_SCREENSHOTS"])
    # a laps-only file: refused in the banner, nothing written
    assert stage.import_heart_rate([str(DATA / "laps-only-fr60.fit")])
    qtbot.waitUntil(lambda: stage.banner.text().startswith("Import refused"), timeout=30_000)
    assert "laps only" in stage.banner.text()
    assert sorted(lab.glob("P07_*")) == folders


def test_import_refused_until_the_form_is_complete(stage):
    stage.form.code.setText("P09")
    assert not stage.import_heart_rate([str(DATA / "garmin-fenix5-run.fit")])
    assert stage.banner.text().startswith("Import refused: ")
    assert not list(stage.session.out_dir.glob("P09_*"))
