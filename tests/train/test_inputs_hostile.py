"""Issue 29: ``train`` refuses an explicit empty folder; ``session.json`` numbers are checked by field."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import pytest

from effortface.core.session.folder import read_session_info
from effortface.cli import main
from effortface.core.errors import SessionFormatError

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "sample_sessions"
SESSION = "P01_20260112-093000_cardio"


def test_train_refuses_an_explicit_empty_folder(tmp_path, capsys) -> None:
    (tmp_path / "EMPTY").mkdir()
    code = main(["train", str(SAMPLE / SESSION), str(tmp_path / "EMPTY"), "--out", str(tmp_path / "model")])
    err = capsys.readouterr().err
    assert code == 2 and f"{tmp_path / 'EMPTY'}: expected a session folder or a folder of sessions, found a " \
                          "folder with none" in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "model").exists()


def _session(tmp_path: Path, edit) -> Path:
    folder = Path(shutil.copytree(SAMPLE / SESSION, tmp_path / SESSION,
                                  ignore=shutil.ignore_patterns("video.avi", "serial")))
    doc = json.loads((folder / "session.json").read_text())
    edit(doc)
    (folder / "session.json").write_text(json.dumps(doc))
    return folder


@pytest.mark.parametrize(("edit", "message"), [
    (lambda d: d["devices"].setdefault("camera", {}).update(fps=math.nan),
     "field 'devices.camera.fps': expected a number above 0 and at most 1000 Hz, found nan"),
    (lambda d: d["devices"].setdefault("camera", {}).update(fps=-1),
     "field 'devices.camera.fps': expected a number above 0 and at most 1000 Hz, found -1"),
    (lambda d: d.setdefault("stats", {}).update(video_frames=-7),
     "field 'stats.video_frames': expected a number from 0 to 1e+15, found -7"),
])
def test_absurd_session_numbers_are_refused_naming_the_field(tmp_path, capsys, edit, message) -> None:
    folder = _session(tmp_path, edit)
    with pytest.raises(SessionFormatError, match=None) as info:
        read_session_info(folder)
    assert message in str(info.value) and str(folder / "session.json") in str(info.value)
    assert main(["export", "bids", str(tmp_path), "--out", str(tmp_path.parent / f"{tmp_path.name}-ds")]) == 2
    assert message in capsys.readouterr().err


def test_an_svr_npz_linked_to_a_text_file_is_not_called_pickled(tmp_path, make_bundle) -> None:
    from effortface.synth.bundle import read_bundle, write_bundle
    model = write_bundle(make_bundle(), tmp_path / "model")
    (tmp_path / "notes.txt").write_text("not arrays\n")
    (model / "svr.npz").unlink()
    (model / "svr.npz").symlink_to(tmp_path / "notes.txt")
    with pytest.raises(Exception) as info:
        read_bundle(model)
    assert "svr.npz" in str(info.value) and "pickled" not in str(info.value)
    assert "neither a zip of arrays nor a .npy" in str(info.value)
