"""``effortface train --raters humans|humans+machine``: the machine labels only the seconds no human
keyed; recorded in model.json and the model card; the report compares both label sets on human labels."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from effortface.annotate.machine.track import FOUR, read_machine_track
from effortface.cli import main
from effortface.train.dataset import MACHINE_PREFIX, DatasetError, session_table
from tests.annotate.machine_helpers import write_fake_machine

ROOT = Path(__file__).resolve().parents[2]
SAMPLES = ROOT / "sample_sessions"
SESSIONS = ("P01_20260112-093000_cardio", "P02_20260119-121100_cardio", "P03_20260113-094400_cardio",
            "P04_20260120-123300_cardio")
UNKEYED = SESSIONS[1]  # its human annotations are removed: the machine labels it


@pytest.fixture(scope="module")
def lab(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Four sample sessions with machine tracks; one has no human key-frame."""
    out = tmp_path_factory.mktemp("raters") / "lab"
    for name in SESSIONS:
        shutil.copytree(SAMPLES / name, out / name, ignore=shutil.ignore_patterns("serial"))
        write_fake_machine(out / name)
    shutil.rmtree(out / UNKEYED / "annotations")
    return out


def test_machine_labels_only_where_no_human_keyed(lab: Path) -> None:
    keyed = session_table(lab / SESSIONS[0], raters="humans+machine")
    humans = session_table(lab / SESSIONS[0])
    for name in FOUR:
        assert not keyed[MACHINE_PREFIX + name].any()  # complete human tracks: the machine adds nothing
        np.testing.assert_array_equal(keyed[name].to_numpy(), humans[name].to_numpy())
    assert not any(c.startswith(MACHINE_PREFIX) for c in humans.columns)
    machine = session_table(lab / UNKEYED, raters="humans+machine")
    track = read_machine_track(lab / UNKEYED)
    for j, name in enumerate(FOUR):
        for t in (30.0, 300.0):
            i = int(np.argmin(np.abs(track.t_s - t)))
            got = float(machine.loc[machine.t_s == t, name].iloc[0])
            if track.face[i]:
                assert got == pytest.approx(track.weights[i, j], abs=1e-4)
        no_face = ~track.face[[int(np.argmin(np.abs(track.t_s - t))) for t in machine.t_s]]
        assert no_face.any() and np.all(np.isnan(machine[name].to_numpy()[no_face]))  # no face, no label
        assert machine[MACHINE_PREFIX + name].to_numpy()[~no_face].all()
    with pytest.raises(DatasetError, match="annotations"):  # the default policy still wants human keys
        session_table(lab / UNKEYED)


def test_train_humans_plus_machine_records_and_compares(lab: Path, tmp_path: Path,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "model"
    assert main(["train", str(lab), "--raters", "humans+machine", "--out", str(out)]) == 0
    doc = json.loads((out / "model.json").read_text())
    prov, metrics = doc["provenance"], doc["metrics"]
    assert prov["raters"] == "humans+machine"
    assert all(n > 500 for n in prov["machine_labelled_seconds"].values())  # the unkeyed session, less no-face
    rows = metrics["face_label_comparison"]
    assert [r["labels"] for r in rows] == ["humans"] * 4 + ["humans+machine"] * 4
    by = {(r["blendshape"], r["labels"]): r for r in rows}
    for name in FOUR:  # both fits are scored on the same held-out human labels
        assert by[(name, "humans")]["n"] == by[(name, "humans+machine")]["n"] > 100
        assert by[(name, "humans")]["r"] != by[(name, "humans+machine")]["r"]
    card = (out / "MODEL_CARD.md").read_text()
    assert "- raters: humans+machine (the machine rater's weights" in card
    assert "human labels only against human + machine labels" in card
    agreement = {r["blendshape"]: r for r in metrics["machine_agreement"]}  # the machine vs the humans
    assert sorted(agreement) == sorted(FOUR)
    for name in FOUR:  # human-keyed sessions only: three of the four, less the fake track's blank stretches
        row = agreement[name]
        assert row["n"] > 500
        assert -1.0 <= row["icc_a1_ci_low"] <= row["icc_a1"] <= row["icc_a1_ci_high"] <= 1.0
        assert np.isfinite([row["r"], row["mad_pct"]]).all() and row["mad_pct"] > 0
    assert "The machine rater's agreement with the humans on this training data" in card
    table = card.split("The machine rater's agreement with the humans")[1]
    assert "| blendshape | n | icc_a1 | icc_a1_ci_low | icc_a1_ci_high | r | mad_pct |" in table
    assert f"| mouth_open | {agreement['mouth_open']['n']} | {agreement['mouth_open']['icc_a1']:.3g} |" in table
    report = (out / "report" / "report.md").read_text()
    assert "## Human labels only against human + machine labels" in report
    assert "- raters: humans+machine" in report


def test_default_raters_are_the_humans(lab: Path, tmp_path: Path) -> None:
    keyed = tmp_path / "keyed"
    keyed.mkdir()
    for name in (SESSIONS[0], SESSIONS[2], SESSIONS[3]):
        (keyed / name).symlink_to(lab / name)
    out = tmp_path / "model"
    assert main(["train", str(keyed), "--out", str(out)]) == 0
    doc = json.loads((out / "model.json").read_text())
    assert doc["provenance"]["raters"] == "humans" and "face_label_comparison" not in doc["metrics"]
    assert "- raters: humans (human key-frames only)" in (out / "MODEL_CARD.md").read_text()


def test_bad_raters_are_one_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    table = tmp_path / "t.csv"
    table.write_text("participant\n")
    assert main(["train", "--table", str(table), "--raters", "humans+machine", "--out", str(tmp_path / "m")]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1
    assert "--raters humans+machine: expected session folders (a table holds no machine track), found --table" in err
    with pytest.raises(SystemExit) as stop:
        main(["train", "--table", str(table), "--raters", "machine", "--out", str(tmp_path / "m")])
    assert stop.value.code == 2 and "invalid choice: 'machine'" in capsys.readouterr().err


def test_train_stage_raters_box_offers_humans_plus_machine(qtbot, lab: Path, tmp_path: Path) -> None:
    from PySide6 import QtCore

    from effortface.train.gui.train_stage import QtTrainStage
    from effortface.train.train_session import TrainSession

    view = QtTrainStage(TrainSession(lab))
    qtbot.addWidget(view)
    try:
        box = view.settings_panel.sources
        assert [box.itemData(i) for i in range(box.count())] == ["humans", "humans+machine"]
        assert view.session.settings.raters == "humans"
        box.setCurrentIndex(box.findData("humans+machine"))
        assert view.session.settings.raters == "humans+machine"
        view.picker.select_shown_button.click()
        view.settings_panel.max_rows.setValue(60)
        qtbot.mouseClick(view.train_button, QtCore.Qt.MouseButton.LeftButton)
        qtbot.waitUntil(lambda: not view.session.busy and view.train_button.isEnabled(), timeout=120_000)
        outcome = view.session.outcome
        assert outcome is not None, view.status.text()
        assert list(outcome.label_comparison["labels"].unique()) == ["humans", "humans+machine"]
        out = tmp_path / "model"
        assert view.export(out)
        qtbot.waitUntil(lambda: not view.session.busy and (out / "MODEL_CARD.md").exists(), timeout=120_000)
        view.session.poll()
        assert json.loads((out / "model.json").read_text())["provenance"]["raters"] == "humans+machine"
    finally:
        view.shutdown()
        view.session.wait(30)


ACCEPTED = "P02_20260119-121100_cardio"  # its only track: keys a rater accepted from the machine, not edited


def _accept_everything(session_dir: Path, rater: str = "R4") -> None:
    """The rater's whole pass: Accept machine on each blendshape over the whole video (no edit)."""
    from effortface.annotate.annotate_session import AnnotateSession

    s = AnnotateSession(session_dir, rater)
    try:
        for name in s.blendshape_names:
            s.set_blendshape(name)
            s.set_frame(0)
            s.accept_machine(0, s.n_frames - 1)
            s.set_frame(s.n_frames - 1)  # the pass is done
    finally:
        s.close()


@pytest.fixture(scope="module")
def accepted_lab(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Three human-keyed cardio sessions and one whose only track is the machine's, accepted by R4."""
    out = tmp_path_factory.mktemp("accepted") / "lab"
    for name in (SESSIONS[0], ACCEPTED, SESSIONS[2], SESSIONS[3]):
        shutil.copytree(SAMPLES / name, out / name, ignore=shutil.ignore_patterns("serial"))
    shutil.rmtree(out / ACCEPTED / "annotations")
    write_fake_machine(out / ACCEPTED, no_face=False)
    _accept_everything(out / ACCEPTED)
    return out


def test_humans_training_leaves_out_a_session_of_accepted_machine_keys(accepted_lab: Path, tmp_path: Path) -> None:
    from effortface.annotate.completeness import rater_status
    from effortface.annotate.keyframes import read_annotations

    ann = read_annotations(accepted_lab / ACCEPTED / "annotations" / "R4.json")
    from effortface.core.session.folder import read_session

    frame_times = read_session(accepted_lab / ACCEPTED).frame_times_s
    assert all(st.complete for st in rater_status(ann, frame_times).values())  # complete, but the machine's
    assert {k.origin for t in ann.tracks.values() for k in t.keys} == {"machine"}
    out = tmp_path / "model"
    assert main(["train", str(accepted_lab), "--out", str(out)]) == 0
    prov = json.loads((out / "model.json").read_text())["provenance"]
    assert prov["n_sessions"] == 3 and prov["raters"] == "humans"
    left_out = prov["label_origins"]["left_out"]
    assert len(left_out) == 1 and left_out[0].startswith(f"{ACCEPTED}: left out: its complete tracks are keys "
                                                         "accepted from the machine, not edited")
    seconds = prov["label_origins"]["seconds"]
    assert seconds["machine"] >= 4 * 600 and seconds["typed"] > 3 * 4 * 500 and seconds["edited"] == 0
    card = (out / "MODEL_CARD.md").read_text()
    assert f"- session left out: {ACCEPTED}: left out" in card
    assert f"keys accepted from the machine and not edited {seconds['machine']} (not human labels" in card


def test_an_edited_machine_key_is_the_raters_label(accepted_lab: Path, tmp_path: Path) -> None:
    from effortface.annotate.annotate_session import AnnotateSession

    lab = tmp_path / "lab"
    shutil.copytree(accepted_lab / ACCEPTED, lab / ACCEPTED)
    s = AnnotateSession(lab / ACCEPTED, "R4")
    try:
        s.set_blendshape("mouth_open")
        key = s.track.keys[len(s.track) // 2]
        s.set_frame(key.frame)
        s.set_key(0.55)  # the rater edits one key
    finally:
        s.close()
    table = session_table(lab / ACCEPTED)  # no longer left out: one human label
    labelled = table["mouth_open"].notna()
    others = ["mouth_stretch", "eye_squint", "brow_lower"]
    assert 0 < labelled.sum() < 10 and table[others].isna().all().all()  # the others are still the machine's
    frame_t = np.asarray(s.session.frame_times_s)
    t_labelled = table.loc[labelled, "t_s"].to_numpy()
    assert np.all(np.abs(t_labelled - frame_t[key.frame]) < 6.0)  # around the edited key only
    nearest = [int(np.argmin(np.abs(frame_t - t))) for t in t_labelled]
    np.testing.assert_allclose(table.loc[labelled, "mouth_open"], s.track.evaluate(nearest))
    assert s.track.get(key.frame).origin == "edited" and s.track.get(key.frame).weight == 0.55
