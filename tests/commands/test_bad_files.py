"""Issue 17, the file cases: every bad file or option is one line naming it (exit 2), never a
traceback, a hang, a memory error or a NaN output; --force never destroys an input.

Cases 3 (rater lock) and 12's Annotate part are in tests/annotate/test_rater_lock.py; case 12's
export folder in tests/train/test_export.py. Tables of ``{message_regex: bad_input}`` (MNE style).
"""

from __future__ import annotations

import io
import json
import os
import re
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from effortface.annotate.keyframes import AnnotationFormatError, read_annotations
from effortface.core.session.folder import check_session, read_session, read_session_info
from effortface.cli import main
from effortface.core import bounds
from effortface.core.errors import SessionFormatError, UserError
from effortface.synth import npzio
from effortface.synth.bundle import BundleFormatError, read_bundle, write_bundle
from effortface.train.dataset import DatasetError, session_table
from effortface.synth.work import write_work
from effortface.synth.work import WorkError, read_motion_index
from effortface.synth.physiology import PhysiologyParams
from effortface.synth.runtime import Character

ROOT = Path(__file__).resolve().parents[2]
SAMPLES = ROOT / "sample_sessions"
SESSION = "P03_20260113-094400_cardio"
OTHER = "P01_20260112-093000_cardio"
JJ = "motion/cmu_13_29_jumping_jacks_120fps.bvh"
DEEP = "[" * 100_000 + "]" * 100_000


def _one_line(capsys: pytest.CaptureFixture, command: str, pattern: str) -> str:
    """The single stderr line of a refused command, checked against ``pattern``."""
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith(f"effortface {command}: error: "), err
    assert re.search(pattern, err), err
    return err


@pytest.fixture
def session(tmp_path: Path) -> Path:
    """A copy of one sample session with its video and annotations (no serial logs)."""
    dst = tmp_path / "lab" / SESSION
    shutil.copytree(SAMPLES / SESSION, dst, ignore=shutil.ignore_patterns("serial"))
    return dst


def _replace_line(path: Path, line_no: int, text: str) -> None:
    lines = path.read_text().splitlines()
    lines[line_no] = text
    path.write_text("\n".join(lines) + "\n")


def _set_json(path: Path, **changes) -> None:
    doc = json.loads(path.read_text())
    doc.update(changes)
    path.write_text(json.dumps(doc))


def _fifo(path: Path) -> None:
    path.unlink()
    os.mkfifo(path)


# ------------------------------------------------------------ case 8 and 12: session files


SESSION_FILES = {
    r"session.json: expected JSON nested at most 32 levels, found 100000":
        lambda s: (s / "session.json").write_text(DEEP),
    r"session.json: expected schema_version 1, found True":
        lambda s: _set_json(s / "session.json", schema_version=True),
    r"heart_rate.csv: expected a heart-rate CSV file, found a special file \(FIFO":
        lambda s: _fifo(s / "heart_rate.csv"),
    r"events.csv: expected a CSV file, found a special file":
        lambda s: _fifo(s / "events.csv"),
    r"session.json: expected JSON \(session.json\), found a special file":
        lambda s: ((s / "session.json").unlink(), (s / "session.json").symlink_to("/dev/zero")),
    r"heart_rate.csv: line 2: expected a heart-rate row, .*t_s: expected a number from 0 to 1e\+06 s, found 1e\+12":
        lambda s: _replace_line(s / "heart_rate.csv", 1, "1e12,80.0,,,sim,1"),
    r"heart_rate.csv: line 3: .*t_s: expected a number from 0 to 1e\+06 s, found nan":
        lambda s: _replace_line(s / "heart_rate.csv", 2, "nan,80.0,,,sim,1"),
    r"events.csv: line 2: expected t_s,kind,label,value, .*t_s: expected a number from 0 to 1e\+06 s, found -5\)":
        lambda s: _replace_line(s / "events.csv", 1, "-5.0,marker,x,"),
    r"video_frames.csv: line 4: expected frame,t_s, .*found nan":
        lambda s: _replace_line(s / "video_frames.csv", 3, "2,nan"),
}


@pytest.mark.parametrize(("message", "corrupt"), SESSION_FILES.items(), ids=list(SESSION_FILES))
def test_bad_session_files_are_one_line(session: Path, message: str, corrupt) -> None:
    corrupt(session)
    with pytest.raises(SessionFormatError, match=message) as info:
        read_session(session)  # returns at once: a FIFO is refused before it is opened
    assert "\n" not in str(info.value)


def test_a_deep_session_json_does_not_stop_the_annotate_stage(qtbot, session: Path) -> None:
    from effortface.annotate.gui.annotate_stage import QtAnnotateStage

    shutil.copytree(SAMPLES / OTHER, session.parent / OTHER, ignore=shutil.ignore_patterns("serial", "*.avi"))
    (session.parent / OTHER / "session.json").write_text(DEEP)
    stage = QtAnnotateStage(session.parent, cache_frames=8)  # the whole folder is listed
    qtbot.addWidget(stage)
    texts = [stage.sessions.item(i).text() for i in range(stage.sessions.count())]
    assert any("unreadable session.json" in t for t in texts) and any(SESSION in t for t in texts)
    stage.shutdown()


ANNOTATION_FILES = {
    r"R1.json: expected JSON nested at most 32 levels": lambda d: DEEP,
    r"R1.json: schema_version: expected 1 or 2, found True": lambda d: json.dumps({**d, "schema_version": True}),
    r"R1.json: session_id: expected 'P03_20260113-094400_cardio' \(this file's session\), found 'P01_":
        lambda d: json.dumps({**d, "session_id": OTHER}),
    r"R1.json: rater: expected 'R1' \(this file's name\), found 'R2'": lambda d: json.dumps({**d, "rater": "R2"}),
}


@pytest.mark.parametrize(("message", "corrupt"), ANNOTATION_FILES.items(), ids=list(ANNOTATION_FILES))
def test_bad_annotation_files(session: Path, message: str, corrupt) -> None:
    path = session / "annotations" / "R1.json"
    path.write_text(corrupt(json.loads(path.read_text())))
    with pytest.raises(AnnotationFormatError, match=message):
        read_annotations(path, session_id=SESSION, rater="R1")


# ---------------------------------------------------- case 11: corrupt sessions before any use


def _swap_frame_times(s: Path) -> None:
    lines = (s / "video_frames.csv").read_text().splitlines()
    t3, t4 = lines[3].split(",")[1], lines[4].split(",")[1]
    lines[3], lines[4] = f"2,{t4}", f"3,{t3}"
    (s / "video_frames.csv").write_text("\n".join(lines) + "\n")


def _drop_last_frame(s: Path) -> None:
    lines = (s / "video_frames.csv").read_text().splitlines()
    (s / "video_frames.csv").write_text("\n".join(lines[:-1]) + "\n")


def _foreign_annotation(s: Path) -> None:
    shutil.copy(SAMPLES / OTHER / "annotations" / "R1.json", s / "annotations" / "R1.json")


def _unsorted_work(s: Path) -> None:
    write_work(s)  # the lab keeps no work.csv (as a capture): `effortface work` makes one, then it is shuffled
    work = pd.read_csv(s / "work.csv")
    work.iloc[::-1].to_csv(s / "work.csv", index=False)


CORRUPT_SESSIONS = {
    r"video_frames.csv: t_s decreases 1 times": _swap_frame_times,
    r"video_frames.csv: expected one row per frame of video.avi \(\d+ frames\), found \d+ rows": _drop_last_frame,
    r"annotations/R1.json: session_id: expected 'P03_20260113-094400_cardio'": _foreign_annotation,
    r"annotations/R2.json: rater: expected 'R2' \(this file's name\), found 'R1'":
        lambda s: shutil.copy(s / "annotations" / "R1.json", s / "annotations" / "R2.json"),
    r"work.csv: line 3: t_s: expected times increasing \(rows sorted by time\), found 628 after 629": _unsorted_work,
    r"heart_rate.csv: line 2: .*found nan": lambda s: _replace_line(s / "heart_rate.csv", 1, "nan,80,,,sim,1"),
}


@pytest.mark.parametrize(("message", "corrupt"), CORRUPT_SESSIONS.items(), ids=list(CORRUPT_SESSIONS))
def test_train_and_evaluate_refuse_corrupt_sessions(session: Path, message: str, corrupt) -> None:
    corrupt(session)
    with pytest.raises(UserError, match=message) as info:
        session_table(session)
    assert "\n" not in str(info.value)


def test_check_session_accepts_every_sample_session() -> None:
    for folder in sorted(p for p in SAMPLES.iterdir() if (p / "session.json").is_file()):
        assert check_session(folder).frame_times_s


def test_train_cli_refuses_a_corrupt_session_in_one_line(session: Path, tmp_path: Path, capsys, make_bundle) -> None:
    _swap_frame_times(session)
    assert main(["train", str(session), "--out", str(tmp_path / "m"), "--max-rows", "20"]) == 2
    _one_line(capsys, "train", r"video_frames.csv: t_s decreases 1 times")
    model = write_bundle(make_bundle(), tmp_path / "model")
    assert main(["evaluate", str(model), str(session)]) == 2
    _one_line(capsys, "evaluate", r"video_frames.csv: t_s decreases 1 times")


# ------------------------------------------------------------------- case 8: motion.json


MOTION_INDEX = {
    r"motion.json: files\[0\]: expected \{path: str, offset_s: number\}, found 5": {"files": [5]},
    r"motion.json: files\[0\]: expected \{path: str, offset_s: number\}, found \{'path': \['a'\]\}":
        {"files": [{"path": ["a"]}]},
    r"motion.json: files\[0\].offset_s: expected a number from -1e\+06 to 1e\+06 s, found 'x'":
        {"files": [{"path": "a.bvh", "offset_s": "x"}]},
    r"motion.json: files\[0\].load_back_kg: expected a number from 0 to 500 kg, found 1e\+308":
        {"files": [{"path": "a.bvh", "load_back_kg": 1e308}]},
    r'motion.json: expected \{"files": \[\{path, offset_s\}\]\}, found list': [1, 2],
}


@pytest.mark.parametrize(("message", "doc"), MOTION_INDEX.items(), ids=list(MOTION_INDEX))
def test_bad_motion_index(tmp_path: Path, message: str, doc) -> None:
    path = tmp_path / "motion.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(WorkError, match=message):
        read_motion_index(path)


def test_deep_motion_index(tmp_path: Path) -> None:
    path = tmp_path / "motion.json"
    path.write_text('{"files": ' + DEEP + "}")
    with pytest.raises(WorkError, match="nested at most 32 levels"):
        read_motion_index(path)


# ------------------------------------------------------------ cases 8, 10, 12: model files


def _edit(folder: Path, edit) -> None:
    path = folder / "model.json"
    doc = json.loads(path.read_text())
    edit(doc)
    path.write_text(json.dumps(doc))


def _npz_member_lies(folder: Path) -> None:
    """A zip bomb in small: one member's header declares 3.2 TB of floats."""
    with np.load(folder / "svr.npz") as npz:
        arrays = {k: npz[k] for k in npz.files}
    with zipfile.ZipFile(folder / "svr.npz", "w") as zf:
        for name, arr in arrays.items():
            buf = io.BytesIO()
            if name == "intercept":
                np.lib.format.write_array_header_1_0(buf, {"descr": "<f8", "fortran_order": False,
                                                           "shape": (10 ** 11, 4)})
                buf.write(b"\0" * 64)
            else:
                np.save(buf, arr)
            zf.writestr(name + ".npy", buf.getvalue())


def _npz_name_not_utf8(folder: Path) -> None:
    """A member name flagged UTF-8 that is not (found by benchmarks/fuzz_long.py: UnicodeDecodeError)."""
    with np.load(folder / "svr.npz") as npz:
        arrays = {k: npz[k] for k in npz.files}
    with zipfile.ZipFile(folder / "svr.npz", "w") as zf:
        for name, arr in arrays.items():
            buf = io.BytesIO()
            np.save(buf, arr)
            zf.writestr(("\u00e9" if name == "intercept" else "") + name + ".npy", buf.getvalue())  # flagged UTF-8
    raw = (folder / "svr.npz").read_bytes()
    (folder / "svr.npz").write_bytes(raw.replace("\u00e9intercept".encode(), b"\xa0\xa0intercept"))


MODELS = {
    r"model.json: expected JSON nested at most 32 levels": lambda f: (f / "model.json").write_text(DEEP),
    r"model.json: schema_version: expected 1, found True": lambda f: _edit(f, lambda d: d.update(schema_version=True)),
    r"model.json.svr\[0\].gamma: expected a number above 0 and at most 1e\+06, found 1e\+308":
        lambda f: _edit(f, lambda d: d["svr"][0].update(gamma=1e308)),
    r"model.json.svr\[1\].C: expected a number above 0 and at most 1e\+06, found 1e\+300":
        lambda f: _edit(f, lambda d: d["svr"][1].update(C=1e300)),
    r"model.json.physiology.update_period_s: expected a number from 0.001 to 60 s, found 1e-300":
        lambda f: _edit(f, lambda d: d["physiology"].update(update_period_s=1e-300)),
    r"model.json.physiology.update_period_s: expected a number from 0.001 to 60 s, found 1e-06":
        lambda f: _edit(f, lambda d: d["physiology"].update(update_period_s=1e-6)),
    r"model.json.physiology.epoc.tau_s: expected a number above 0 and at most 1e\+06 s, found 1e\+200":
        lambda f: _edit(f, lambda d: d["physiology"]["epoc"].update(tau_s=1e200)),
    r"model.json.scaler.scale\[2\]: expected a number from 1e-09 to 1e\+06, found 1e-300":
        lambda f: _edit(f, lambda d: d["scaler"]["scale"].__setitem__(2, 1e-300)),
    r"model.json.scaler.mean: expected 4 finite numbers, found \[1000000000": lambda f: _edit(
        f, lambda d: d["scaler"]["mean"].__setitem__(0, 10 ** 400)),  # found by benchmarks/fuzz_long.py
    r"model.json.nhr.tl_regression.t_root.intercept: expected a finite number, found 1000000000": lambda f: _edit(
        f, lambda d: d["nhr"]["tl_regression"]["t_root"].update(intercept=10 ** 400)),
    r"svr.npz: intercept.npy: expected an array of at most \d+ bytes \(its stored size\), found a header "
    r"declaring shape \(100000000000, 4\)": _npz_member_lies,
    r"svr.npz: expected a numpy .npz without pickles, found 'utf-8' codec can't decode byte 0xa0":
        _npz_name_not_utf8,
    r"model.json: expected JSON \(model.json\), found a special file": lambda f: (
        (f / "model.json").unlink(), os.mkfifo(f / "model.json")),
}


@pytest.mark.parametrize(("message", "corrupt"), MODELS.items(), ids=list(MODELS))
def test_bad_models_are_one_line(tmp_path: Path, message: str, corrupt, make_bundle) -> None:
    folder = write_bundle(make_bundle(), tmp_path / "m")
    corrupt(folder)
    with pytest.raises(BundleFormatError, match=message) as info:
        read_bundle(folder)
    assert "\n" not in str(info.value)


def test_npz_content_over_the_limit(tmp_path: Path, monkeypatch, make_bundle) -> None:
    folder = write_bundle(make_bundle(), tmp_path / "m")
    monkeypatch.setattr(npzio, "MAX_NPZ_BYTES", 1000)
    with pytest.raises(BundleFormatError, match=r"svr.npz: expected at most 1000 bytes of arrays"):
        read_bundle(folder)


def test_runtime_bounds_update_period_and_character() -> None:
    with pytest.raises(UserError, match=r"update_period_s: expected a number from 0.001 to 60 s, found 1e-300"):
        PhysiologyParams.from_character(Character(), update_period_s=1e-300)
    with pytest.raises(UserError, match=r"mass_kg: expected a number from 15 to 300 kg, found 1e\+308"):
        Character(mass_kg=1e308).loads()
    with pytest.raises(UserError, match=r"load_left_kg: expected a number from 0 to 500 kg, found 1e\+308"):
        Character(load_left_kg=1e308)


# ------------------------------------------------- case 10: absurd options, case 5: --force


def test_absurd_character_options_are_refused_before_nan(shared_data: Path, tmp_path: Path, capsys) -> None:
    clip, out = str(shared_data / JJ), tmp_path / "o.csv"
    assert main(["synth", "default", clip, "--out", str(out), "--mass", "1e308"]) == 2
    _one_line(capsys, "synth", r"mass_kg: expected a number from 15 to 300 kg, found 1e\+308")
    assert main(["synth", "default", clip, "--out", str(out), "--load-back", "1e308"]) == 2
    _one_line(capsys, "synth", r"load_back_kg: expected a number from 0 to 500 kg, found 1e\+308")
    assert main(["synth", "default", clip, "--out", str(out), "--unit-m", "1e308"]) == 2
    _one_line(capsys, "synth", r"--unit-m: expected a number above 0 and at most 100 m, found 1e\+308")
    assert not out.exists()


def test_synth_force_never_overwrites_its_inputs(shared_data: Path, tmp_path: Path, capsys, make_bundle) -> None:
    clip = tmp_path / "clip.bvh"
    shutil.copy(shared_data / JJ, clip)
    before = clip.read_bytes()
    assert main(["synth", "default", str(clip), "--out", str(clip), "--force"]) == 2
    _one_line(capsys, "synth", r"--out \S+clip.bvh: expected an output apart from the inputs, found input \S+clip.bvh$")
    link = tmp_path / "link.csv"
    link.symlink_to(clip)
    assert main(["synth", "default", str(clip), "--out", str(link), "--force"]) == 2
    _one_line(capsys, "synth", r"found input \S+clip.bvh")
    assert clip.read_bytes() == before
    model = write_bundle(make_bundle(), tmp_path / "model")
    model_json = (model / "model.json").read_bytes()
    assert main(["synth", str(model), str(clip), "--out", str(model / "model.json"), "--force"]) == 2
    _one_line(capsys, "synth", r"--out \S+model.json: expected an output apart from the inputs, found input "
                               r"\S+model around it")
    assert (model / "model.json").read_bytes() == model_json


def test_train_force_never_deletes_blendshapes_or_linked_sessions(tmp_path: Path, capsys, make_bundle, make_session) -> None:
    from effortface.train.dataset import synthetic_table
    table = synthetic_table(n_participants=3, seconds=120, seed=5)
    model = write_bundle(make_bundle(), tmp_path / "model")  # an existing model: --force may replace it
    shapes = model / "shapes.json"
    shapes.write_text(json.dumps([s for s in json.loads((model / "model.json").read_text())["blendshapes"]]))
    lab = tmp_path / "lab"
    for _, rows in table.groupby("session"):
        make_session(lab, rows.reset_index(drop=True))
    args = ["train", str(lab), "--out", str(model), "--force", "--max-rows", "20"]
    assert main([*args, "--blendshapes", str(shapes)]) == 2
    _one_line(capsys, "train", r"--out \S+model: expected a model folder apart from the inputs, found input "
                               r"\S+shapes.json inside it")
    assert shapes.is_file()
    # a session kept in the model folder and reached through a link from the lab
    first = sorted(lab.iterdir())[0]
    shutil.move(first, model / first.name)
    (lab / first.name).symlink_to(model / first.name)
    assert main(args) == 2
    _one_line(capsys, "train", rf"found input \S+lab inside it \(through a link, at \S+model/{first.name}\)")
    assert (model / first.name / "session.json").is_file()


def test_bounds_table_describes_itself() -> None:
    assert bounds.check("gamma", 0.5) == 0.5
    for bad in (True, "1", float("nan"), float("inf"), None):
        with pytest.raises(UserError, match="gamma: expected a number above 0"):
            bounds.check("gamma", bad)


@pytest.mark.parametrize(("command", "name"), [("synth", "clip.bvh"), ("synth", "clip.npz"), ("train", "t.csv")])
def test_a_fifo_given_as_a_file_is_refused_at_once(tmp_path: Path, capsys, command: str, name: str) -> None:
    fifo = tmp_path / name
    os.mkfifo(fifo)  # reading it would block forever
    args = (["synth", "default", str(fifo), "--out", str(tmp_path / "o.csv")] if command == "synth"
            else ["train", "--table", str(fifo), "--out", str(tmp_path / "m")])
    assert main(args) == 2
    _one_line(capsys, command, rf"{name}: expected a (motion file|CSV table).*, found a special file \(FIFO")


def test_agreement_refuses_a_rater_file_copied_under_another_name(session: Path, capsys) -> None:
    shutil.copytree(SAMPLES / "reliability", session.parent / "reliability")
    shutil.copy(session / "annotations" / "R1.json", session / "annotations" / "R4.json")
    assert main(["agreement", str(session)]) == 2  # R1's keys would have counted twice
    _one_line(capsys, "agreement", r"R4.json: rater: expected 'R4' \(this file's name\), found 'R1'")
