"""The Synthesize stage offscreen: a trained bundle drives the face while a real clip plays.

Trains a small bundle on the sample lab (into tmp_path), loads it in
:class:`effortface.synth.gui.synth_stage.QtSynthStage`, plays the 120 Hz jumping-jacks clip and changes the
character through the controls while it plays; asserts on the model
(:class:`effortface.synth.synth_session.SynthSession`) and on what the views show.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest
from PySide6 import QtCore, QtGui, QtWidgets

from effortface.synth.curves_io import LIVELINK_BLENDSHAPES
from effortface.synth.gui.synth_stage import QtSynthStage
from effortface.synth.runtime import load_model
from effortface.synth.synth_session import SynthSession
from effortface.train.train_session import TrainSession

SAMPLE = Path(__file__).resolve().parents[2] / "sample_sessions"
CLIP = "motion/cmu_13_29_jumping_jacks_120fps.bvh"
LEFT = QtCore.Qt.MouseButton.LeftButton
#: the offscreen platform says this whenever a top-level window is shown (harmless)
pytestmark = pytest.mark.qt_log_ignore("This plugin does not support propagateSizeHints")


@pytest.fixture(scope="module")
def bundle(tmp_path_factory) -> Path:
    """A model trained on the whole sample lab with small settings."""
    out = tmp_path_factory.mktemp("synth_bundle") / "model"
    s = TrainSession(SAMPLE)
    s.set_selected([e.session_id for e in s.entries])
    s.set_settings(max_rows_per_participant=60)
    s.start_training()
    s.wait(120)
    s.export(out)
    s.wait(120)
    assert (out / "model.json").is_file()
    return out


@pytest.fixture
def stage(qtbot, shared_data: Path) -> QtSynthStage:
    view = QtSynthStage(SynthSession(background=True), motion_dir=shared_data / "motion")
    qtbot.addWidget(view)
    view.resize(1200, 800)
    view.show()
    assert view.load_clip(shared_data / CLIP)
    view.session.wait(30)
    yield view
    view.shutdown()


def _play(qtbot, stage: QtSynthStage, frames: int = 3) -> None:
    start = stage.frames_drawn
    if not stage.session.playing:
        qtbot.mouseClick(stage.play_button, LEFT)
    qtbot.waitUntil(lambda: stage.frames_drawn >= start + frames, timeout=10_000)


def test_training_level_changes_nhr_while_playing(qtbot, stage: QtSynthStage) -> None:
    """Built-in model (the paper's TL regression): higher TL -> lower NHR for the same motion."""
    s = stage.session
    stage.loops.setValue(30)                                 # about 110 s of jumping jacks
    s.wait(30)                                               # recomputed on the worker thread
    assert s.loops == 30 and s.n_frames == 30 * s.motion.n_frames
    _play(qtbot, stage)
    assert s.playing and s.position_s > 0
    assert stage.play_button.text() == "Pause"
    assert not stage.face.pixmap().isNull()

    stage.character.fields["training_level"].setValue(0.0)   # through the control, while playing
    s.wait(30)
    nhr_tl0, before = s.curves["nhr"].copy(), s.position_s
    _play(qtbot, stage)
    stage.character.fields["training_level"].setValue(10.0)
    s.wait(30)
    nhr_tl10 = s.curves["nhr"].copy()
    assert s.character.training_level == 10.0 and stage.character.tl_slider.value() == 100
    assert s.position_s >= before                            # the play head kept going, not reset
    assert nhr_tl0[-1] > 0.2 and nhr_tl10[-1] < nhr_tl0[-1] - 0.1
    assert np.all(nhr_tl10 <= nhr_tl0 + 1e-9)
    _play(qtbot, stage)
    x, y = stage.plots.curves["nhr"].getOriginalDataset()
    np.testing.assert_allclose(y, nhr_tl10)                  # the plot shows the new curve
    # the right-hand HR axis reads the NHR curve as HR: its range maps NHR -0.02..1.02 to bpm
    params = s.model.physiology_params(s.character)
    rest, top = float(params.hr_rest_bpm), float(params.hr_max_bpm)
    np.testing.assert_allclose(s.curves["hr_bpm"], rest + s.curves["nhr"] * (top - rest))
    lo, hi = stage.plots._hr_view.viewRange()[1]
    np.testing.assert_allclose([lo, hi], [rest - 0.02 * (top - rest), top + 0.02 * (top - rest)])
    assert f"HR {s.curves['hr_bpm'][s.frame]:.0f} bpm" in stage.time_label.text()


def test_bundle_curves_are_the_runtime_s(qtbot, stage: QtSynthStage, bundle: Path,
                                         shared_data: Path) -> None:
    """A trained bundle in the stage gives exactly what the runtime API gives, after every change."""
    s = stage.session
    assert stage.load_model(bundle)
    s.wait(30)
    assert s.model.name == str(bundle) and stage.model_label.text() == bundle.name
    _play(qtbot, stage)
    model = load_model(bundle)
    for tl in (0.0, 10.0):
        stage.character.fields["training_level"].setValue(tl)
        stage.character.fields["mass_kg"].setValue(60.0 + tl)   # also refreshes the cached work
        s.wait(30)
        expected = model.synthesize(shared_data / CLIP, s.character)
        for key in ("w_per_kg", "nhr", "hr_bpm", "epoc", *model.blendshapes.names):
            np.testing.assert_allclose(s.curves[key], expected[key], rtol=1e-12, atol=1e-12)
    _play(qtbot, stage)
    assert np.isfinite(s.weights_at()).all()


def test_expressiveness_half_halves_a_weight(qtbot, stage: QtSynthStage, bundle: Path) -> None:
    s = stage.session
    stage.load_model(bundle)
    stage.loops.setValue(10)
    s.wait(30)
    _play(qtbot, stage)
    name = s.model.blendshapes.names[0]
    full = s.curves[name].copy()
    stage.character.expressiveness[0].setValue(0.5)
    s.wait(30)
    half = s.curves[name]
    assert s.character.expressiveness[0] == 0.5
    below = (full > 0) & (full < 1)                          # not clipped at expressiveness 1
    assert below.sum() > 100
    np.testing.assert_allclose(half[below], 0.5 * full[below], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(half[full >= 1], np.clip(half[full >= 1], 0.5, 1))
    for other in s.model.blendshapes.names[1:]:
        assert np.isfinite(s.curves[other]).all()
    _play(qtbot, stage)
    label = stage.weights_label.text()
    assert f"{name.replace('_', ' ')} {s.weights_at()[0]:.2f}" in label


def test_loads_raise_work_and_side_view(qtbot, stage: QtSynthStage) -> None:
    s = stage.session
    w0 = s.curves["w_per_kg"].mean()
    stage.character.fields["load_back_kg"].setValue(20.0)
    s.wait(30)
    assert s.character.load_back_kg == 20.0
    assert s.curves["w_per_kg"].mean() > w0
    s.seek(1.0)
    front = stage.skeleton.bones.getData()[0].copy()
    stage.view_combo.setCurrentIndex(1)
    side = stage.skeleton.bones.getData()[0]
    assert stage.skeleton.view == "side"
    assert np.ptp(front) > 2 * np.ptp(side)                  # jumping jacks spread left-right


def test_export_csv_livelink_and_overwrite(qtbot, stage: QtSynthStage, tmp_path: Path) -> None:
    s = stage.session
    out = tmp_path / "curves.csv"
    assert stage.export(out, "csv")
    with out.open() as f:
        rows = list(csv.reader(f))
    assert rows[0] == list(s.model.columns)
    assert len(rows) == 1 + s.n_frames
    np.testing.assert_allclose([float(r[3]) for r in rows[1:]], s.curves["nhr"], atol=1e-9)

    text = out.read_text()
    stage.confirm_overwrite = lambda path: False
    assert not stage.export(out, "livelink")
    assert out.read_text() == text                           # kept
    stage.confirm_overwrite = lambda path: True
    assert stage.export(out, "livelink")
    header = out.read_text().splitlines()[0].split(",")
    assert header[:2] == ["Timecode", "BlendShapeCount"] and header[2:54] == list(LIVELINK_BLENDSHAPES)


def test_bad_inputs_are_shown_and_state_kept(qtbot, stage: QtSynthStage, tmp_path: Path) -> None:
    s = stage.session
    frames = s.n_frames
    bad = tmp_path / "clip.txt"
    bad.write_text("not a clip")
    assert not stage.load_clip(bad)
    assert "b00020" in stage.status.styleSheet() and "clip.txt" in stage.status.text()
    assert s.n_frames == frames
    assert not stage.load_model(tmp_path)                    # a folder without model.json
    assert "model.json" in stage.status.text()
    assert s.model.name.startswith("default")


def test_pick_a_clip_found_in_the_folder(qtbot, stage: QtSynthStage, shared_data: Path) -> None:
    combo = stage.clip_combo
    names = [combo.itemText(i) for i in range(combo.count())]
    assert "cmu_13_29_squats_120fps.bvh" in names and "amp_humanoid_run.npz" in names
    index = names.index("cmu_13_29_squats_120fps.bvh")
    combo.setCurrentIndex(index)
    combo.activated.emit(index)                               # what a user's pick emits
    stage.session.wait(30)
    assert stage.session.motion_path == shared_data / "motion" / "cmu_13_29_squats_120fps.bvh"
    assert stage.session.n_frames == stage.session.motion.n_frames * stage.session.loops
    assert "squats" in stage.clip_label.text()


# --------------------------------------------------------------------------- fixes of the GUI audit


def test_long_names_keep_the_stage_1280_wide(qtbot, stage: QtSynthStage, bundle: Path,
                                             shared_data: Path, tmp_path: Path) -> None:
    """Long clip and model names elide (whole in the tooltip); the status line wraps."""
    import shutil

    folder = tmp_path / "a_rather_deeply_nested_folder_of_motion_capture_takes_from_the_lab"
    folder.mkdir()
    clip = folder / "participant_P02_session_20260112_113700_strength_take_03_retake_final_v2.bvh"
    shutil.copy(shared_data / CLIP, clip)
    model = tmp_path / "bundle_trained_on_all_twelve_sessions_with_the_large_grid_and_mean_raters_v3"
    shutil.copytree(bundle, model)
    assert stage.load_clip(clip) and stage.load_model(model)
    stage.session.wait(30)
    _play(qtbot, stage)
    assert stage.minimumSizeHint().width() <= 1100
    assert clip.name in stage.clip_label.text() and str(clip) in stage.clip_label.toolTip()
    assert stage.model_label.text() == model.name and str(model) in stage.model_label.toolTip()
    assert str(model) in stage.status.text()                 # wrapped, not cut


def test_clip_combo_shows_the_loaded_clip(qtbot, stage: QtSynthStage, shared_data: Path,
                                          tmp_path: Path) -> None:
    import shutil

    combo = stage.clip_combo
    assert combo.currentText() == Path(CLIP).name            # loaded by the fixture, listed
    index = combo.findText("cmu_13_29_squats_120fps.bvh")
    combo.setCurrentIndex(index)
    combo.activated.emit(index)                              # the user picks squats
    assert "squats" in stage.clip_label.text()
    assert stage.load_clip(shared_data / CLIP)               # then opens another listed clip
    assert combo.currentText() == Path(CLIP).name
    elsewhere = tmp_path / "elsewhere.bvh"
    shutil.copy(shared_data / CLIP, elsewhere)
    assert stage.load_clip(elsewhere)                        # a clip not in the list: neutral entry
    assert combo.currentIndex() == 0 and combo.currentData() is None
    assert "elsewhere" in stage.clip_label.text()


def test_clip_combo_elides_a_long_path_in_the_middle(qtbot, stage: QtSynthStage, shared_data: Path) -> None:
    """A clip in a session's motion folder: the box keeps the file name in view (not 'P02_2026...')."""
    from effortface.synth.gui.synth_stage import QtSynthStage as Stage, SynthSession as Session

    view = Stage(Session(background=True), motion_dir=SAMPLE)  # clips under <session>/motion/
    qtbot.addWidget(view)
    try:
        clip = next(SAMPLE.glob("*/motion/*.bvh"))
        assert view.load_clip(clip)
        combo = view.clip_combo
        combo.show()
        assert combo.currentText() == str(clip.relative_to(SAMPLE))
        shown = combo.elided_text()
        assert shown.endswith(clip.name) and "\u2026" in shown
        assert combo.fontMetrics().horizontalAdvance(shown) < combo.width()
    finally:
        view.shutdown()
        view.session.wait(30)


def test_hiding_the_stage_pauses_playback(qtbot, stage: QtSynthStage) -> None:
    """Showing another stage of the main window (a QStackedWidget) pauses the clip."""
    from PySide6 import QtWidgets

    host = QtWidgets.QStackedWidget()
    qtbot.addWidget(host)
    other = QtWidgets.QLabel("another stage")
    host.addWidget(stage)
    host.addWidget(other)
    host.show()
    _play(qtbot, stage)
    assert stage.timer.isActive()
    host.setCurrentWidget(other)
    assert not stage.session.playing and not stage.timer.isActive()
    assert stage.play_button.text() == "Play" and not stage.play_button.isChecked()
    stage.setParent(None)                                    # the fixture, not the host, ends it


# --------------------------------------------------------------------------- issue 16 item 12


def _press(qtbot, widget, key: QtCore.Qt.Key, modifier=QtCore.Qt.KeyboardModifier.NoModifier) -> None:
    """A real key press on the focused widget, through the window system (shortcuts included)."""
    widget.setFocus()
    qtbot.waitUntil(widget.hasFocus, timeout=2_000)
    qtbot.keyClick(widget, key, modifier)


def test_space_plays_and_keys_seek_from_any_focus(qtbot, stage: QtSynthStage) -> None:
    """Space, arrows and Home/End drive the player whether the focus is in a spin box, the
    clip list or the plots."""
    stage.activateWindow()
    tl = stage.character.fields["training_level"]
    tl_before = tl.value()
    _press(qtbot, tl, QtCore.Qt.Key.Key_Space)
    assert stage.session.playing and tl.value() == tl_before
    _press(qtbot, stage.clip_combo, QtCore.Qt.Key.Key_Space)
    assert not stage.session.playing
    _press(qtbot, stage.loops, QtCore.Qt.Key.Key_End)
    assert stage.session.frame == stage.session.n_frames - 1
    _press(qtbot, stage.character.expressiveness[0], QtCore.Qt.Key.Key_Home)
    assert stage.session.frame == 0
    _press(qtbot, tl, QtCore.Qt.Key.Key_Right)
    assert stage.session.frame == 1
    _press(qtbot, stage.plots, QtCore.Qt.Key.Key_Right, QtCore.Qt.KeyboardModifier.ShiftModifier)
    assert stage.session.frame == 1 + round(stage.session.motion.fps)
    assert stage.session.character.training_level == tl_before      # the spin boxes kept their values


def test_keys_are_released_when_the_stage_is_hidden(qtbot, stage: QtSynthStage) -> None:
    other = QtWidgets.QLineEdit()
    qtbot.addWidget(other)
    stage.hide()
    other.show()
    _press(qtbot, other, QtCore.Qt.Key.Key_Space)
    assert other.text() == " " and not stage.session.playing


def test_a_new_clip_starts_at_one_repeat(qtbot, stage: QtSynthStage, shared_data: Path) -> None:
    one_pass_s = stage.session.duration_s
    stage.loops.setValue(40)
    stage.session.wait(30)
    assert stage.session.duration_s > 39 * one_pass_s
    assert stage.load_clip(shared_data / CLIP)
    stage.session.wait(30)
    assert stage.session.loops == 1 and stage.loops.value() == 1
    assert stage.session.duration_s == pytest.approx(one_pass_s)
    assert "repeat reset from 40 x to 1 x" in stage.status.text()


def test_export_suggests_a_file_name(stage: QtSynthStage, bundle: Path, shared_data: Path) -> None:
    clip = shared_data / CLIP
    assert stage.session.default_export_path("csv") == clip.parent / f"{clip.stem}_rule_curves.csv"
    assert stage.load_model(bundle)
    assert stage.session.default_export_path("livelink").name == f"{clip.stem}_{bundle.name}_livelink.csv"


def test_epoc_axis_and_aligned_time_axes(stage: QtSynthStage) -> None:
    from effortface.synth.gui.synth_stage import EPOC_MIN_TOP_ML_PER_KG, epoc_axis_top

    assert epoc_axis_top(np.full(10, 0.0007)) == EPOC_MIN_TOP_ML_PER_KG   # not 0-0.0008
    assert epoc_axis_top(np.array([0.0, 20.0])) == pytest.approx(21.0)
    top = stage.plots.plots["epoc"].vb.viewRange()[1][1]
    assert top >= EPOC_MIN_TOP_ML_PER_KG
    QtWidgets.QApplication.processEvents()
    boxes = [p.vb.sceneBoundingRect() for p in stage.plots.plots.values()]
    lefts = {round(b.left()) - round(min(x.left() for x in boxes[i % 2::2])) for i, b in enumerate(boxes)}
    assert lefts == {0} and len({round(b.width()) for b in boxes}) == 1   # same x geometry
    ranges = {tuple(np.round(p.vb.viewRange()[0], 6)) for p in stage.plots.plots.values()}
    assert len(ranges) == 1                                                 # one time axis


def test_no_weight_curve_hides_under_another(stage: QtSynthStage) -> None:
    names = stage.session.model.blendshapes.names
    pens = [stage.plots.curves[n].opts["pen"] for n in names]
    widths = [p.widthF() for p in pens]
    assert widths == sorted(widths, reverse=True) and len(set(widths)) == len(widths)
    assert all(p.color().alpha() < 255 for p in pens)
    z = [stage.plots.curves[n].zValue() for n in names]
    assert z == sorted(z)                       # the thinnest drawn last, on top


def test_face_preview_grows_with_the_window(qtbot, stage: QtSynthStage) -> None:
    stage.resize(1280, 800)
    qtbot.waitUntil(lambda: stage.face.pixmap().width() >= 320, timeout=2_000)
    small = stage.face.pixmap().width()
    stage.resize(1920, 1080)
    qtbot.waitUntil(lambda: stage.face.pixmap().width() > small, timeout=2_000)


def test_character_panel_fits_at_1280x800(qtbot, stage: QtSynthStage) -> None:
    stage.resize(1280, 800)
    QtWidgets.QApplication.processEvents()
    bar = stage.character_scroll.verticalScrollBar()
    assert bar.maximum() == 0           # nothing of the character panel scrolled out


def test_mapping_button_maps_an_unknown_skeleton(qtbot, stage: QtSynthStage, tmp_path: Path) -> None:
    """A clip whose skeleton no built-in convention knows: an error line, then curves once a mapping is
    chosen (the Mapping... button's path); a mapping that does not fit is refused and the old one kept."""
    import json

    data = Path(__file__).resolve().parents[1] / "data" / "bvh"
    text = (data / "pymo_walk.bvh").read_text().replace("JOINT LeftUpLeg\n", "JOINT Bone07\n")
    clip = tmp_path / "renamed.bvh"
    clip.write_text(text)
    assert stage.load_clip(clip)
    stage.session.wait(60)
    assert "unmapped segments: trunk, left_thigh" in stage.status.text()
    assert stage.mapping_button.isVisible()
    wrong = tmp_path / "wrong.json"
    wrong.write_text(json.dumps({"left_thigh": ["NoSuchJoint", "LeftLeg"]}))
    assert not stage.set_mapping(wrong) and stage.session.mapping is None
    mapping = tmp_path / "map.json"
    ends = {"head": ["Head_end", "Head"], "trunk": ["Head", ["Bone07", "RightUpLeg"]],
            "left_thigh": ["Bone07", "LeftLeg"], "right_thigh": ["RightUpLeg", "RightLeg"]}
    for s, S in (("left", "Left"), ("right", "Right")):
        ends |= {f"{s}_upper_arm": [f"{S}Arm", f"{S}ForeArm"], f"{s}_forearm": [f"{S}ForeArm", f"{S}Hand"],
                 f"{s}_hand": [f"{S}Hand", f"{S}Hand_End"], f"{s}_shank": [f"{S}Leg", f"{S}Foot"],
                 f"{s}_foot": [f"{S}Foot", f"{S}ToeBase_end"]}
    mapping.write_text(json.dumps(ends))
    assert stage.set_mapping(mapping)
    stage.session.wait(60)
    assert stage.session.curves and len(stage.session.curves["t_s"]) == stage.session.n_frames
    assert np.isfinite(stage.session.curves["w_per_kg"]).all()


def test_the_last_trained_model_is_offered(qtbot, bundle: Path, tmp_path: Path) -> None:
    """Issue 25 item 6: the model Train exported last is offered in Synthesize, now and after a restart."""
    from effortface.app import LAST_MODEL_KEY, MainWindow

    settings = QtCore.QSettings(str(tmp_path / "settings.ini"), QtCore.QSettings.Format.IniFormat)
    (tmp_path / "lab").mkdir()
    win = MainWindow(tmp_path / "lab", settings)
    qtbot.addWidget(win)
    synth = win.show_stage("synthesize")
    assert not synth.last_model_button.isVisibleTo(synth)        # nothing trained yet
    win.show_stage("train").session.export_changed.emit(bundle)  # what Train's export says when done
    assert settings.value(LAST_MODEL_KEY) == str(bundle)
    assert synth.last_model_button.isVisibleTo(synth) and synth.last_model_button.text() == "Last trained: model"
    qtbot.mouseClick(synth.last_model_button, LEFT)
    synth.session.wait(30)
    assert synth.session.model.name == str(bundle) or Path(synth.session.model.name) == bundle
    win.shutdown()
    again = MainWindow(tmp_path / "lab", settings)               # the next start offers it too
    qtbot.addWidget(again)
    assert again.show_stage("synthesize").last_model_button.toolTip() == str(bundle)
    again.shutdown()


def test_the_face_can_be_drawn_larger_so_small_weights_show(qtbot, stage: QtSynthStage) -> None:
    """Issue 25 item 6: weights of 0.1-0.25 left the drawn face neutral; "Face drawn at x4" draws the
    weights times 4 (clipped) while the weights shown stay true."""
    from effortface.annotate.face import render_face

    face = stage.face
    assert face.gain == 1.0
    stage.face_gain.setCurrentText("x4")
    face.show_weights(np.full(4, 0.2))
    w, h = face.face_size()
    shown = face.pixmap().toImage().convertToFormat(QtGui.QImage.Format.Format_RGB888)
    pixels = np.frombuffer(shown.constBits(), np.uint8).reshape(h, shown.bytesPerLine())[:, :3 * w].reshape(h, w, 3)
    np.testing.assert_array_equal(pixels, render_face(np.full(4, 0.8), (w, h))[:, :, ::-1])
    assert not np.array_equal(pixels, render_face(np.full(4, 0.2), (w, h))[:, :, ::-1])


def test_each_curve_can_be_hidden_so_none_hides_another(qtbot, stage: QtSynthStage) -> None:
    """Issue 25 item 6: one check box per curve under the plots hides or shows it; a recompute keeps it hidden."""
    qtbot.waitUntil(lambda: bool(stage.curve_boxes), timeout=30000)
    names = stage.session.model.blendshapes.names
    assert set(stage.curve_boxes) == {"w_per_kg", "p_per_kg", "nhr", "epoc", *names}
    first = names[0]
    assert stage.plots.curves[first].isVisible()
    stage.curve_boxes[first].setChecked(False)     # what a click does
    assert not stage.plots.curves[first].isVisible() and stage.plots.curves[names[1]].isVisible()
    stage.curve_boxes["epoc"].click()
    assert not stage.plots.curves["epoc"].isVisible()
    stage._on_curves_changed()                     # a recompute redraws: still hidden
    assert not stage.plots.curves[first].isVisible() and not stage.curve_boxes[first].isChecked()
    stage.curve_boxes[first].click()
    assert stage.plots.curves[first].isVisible()
