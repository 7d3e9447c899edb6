"""A damaged, truncated, swapped or oversized Face Landmarker bundle (``--model`` .task zip) is one line
naming the bundle and the member (issue 37: Flatbuffer ValueError and KeyError tracebacks, and a zip bomb
inflated to gigabytes). Members' sizes are checked before anything is inflated."""

from __future__ import annotations

import re
import shutil
import zipfile
from pathlib import Path

import pytest

from effortface.annotate.machine.landmarker import (BLENDSHAPES_TFLITE, DEFAULT_MODEL, DETECTOR_TFLITE,
                                                    LANDMARKS_TFLITE, MAX_TASK_BYTES, read_bundle)
from effortface.cli import main
from effortface.core.errors import UserError

ROOT = Path(__file__).resolve().parents[2]
SESSION = ROOT / "sample_sessions" / "P01_20260112-093000_cardio"


def _members() -> dict[str, bytes]:
    with zipfile.ZipFile(DEFAULT_MODEL) as z:
        return {i.filename: z.read(i.filename) for i in z.infolist()}


def _write(path: Path, members: dict[str, bytes]) -> Path:
    with zipfile.ZipFile(path, "w") as out:
        for name, data in members.items():
            out.writestr(name, data)
    return path


def _bomb(path: Path) -> Path:
    """A small zip whose landmarks member inflates to 80 MiB of zeros (over MAX_TASK_BYTES)."""
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as out:
        for name in (DETECTOR_TFLITE, BLENDSHAPES_TFLITE):
            out.writestr(name, b"x")
        with out.open(LANDMARKS_TFLITE, "w", force_zip64=True) as fh:
            for _ in range(80):
                fh.write(bytes(1 << 20))
    return path


def test_a_zip_bomb_is_refused_before_inflating(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    bomb = _bomb(tmp_path / "bomb.task")
    assert bomb.stat().st_size < 1_000_000 and 80 * (1 << 20) > MAX_TASK_BYTES
    monkeypatch.setattr(zipfile.ZipFile, "read", lambda *a, **k: pytest.fail("a member was inflated"))
    with pytest.raises(UserError, match=rf"--model {bomb}: expected at most {MAX_TASK_BYTES} bytes of models, "
                                        r"found \d+ or more once uncompressed"):
        read_bundle(bomb)


def test_a_truncated_bundle_is_one_line(tmp_path: Path) -> None:
    data = DEFAULT_MODEL.read_bytes()
    cut = tmp_path / "cut.task"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(UserError, match=r"cut\.task: expected a Face Landmarker bundle \(a zip\), found"):
        read_bundle(cut)


@pytest.fixture
def litert() -> None:
    pytest.importorskip("ai_edge_litert")


def _swapped(tmp_path: Path) -> Path:
    members = _members()
    members[DETECTOR_TFLITE], members[BLENDSHAPES_TFLITE] = members[BLENDSHAPES_TFLITE], members[DETECTOR_TFLITE]
    return _write(tmp_path / "swapped.task", members)


def _damaged(tmp_path: Path) -> Path:
    members = _members()
    members[LANDMARKS_TFLITE] = bytes(64) + members[LANDMARKS_TFLITE][64:]
    return _write(tmp_path / "damaged.task", members)


def _member_cut(tmp_path: Path) -> Path:
    members = _members()
    members[BLENDSHAPES_TFLITE] = members[BLENDSHAPES_TFLITE][:5000]
    return _write(tmp_path / "member_cut.task", members)


@pytest.mark.parametrize("make, message", [
    (_swapped, r"face_detector\.tflite: expected the Face Landmarker model with outputs regressors, classificators, "
               r"found StatefulPartitionedCall:0 \(a swapped or foreign model\?\)"),
    (_damaged, r"face_landmarks_detector\.tflite: expected a TFLite model, found one the runtime cannot load"),
    (_member_cut, r"face_blendshapes\.tflite: expected a TFLite model, found one the runtime cannot load"),
], ids=["swapped", "damaged", "member-truncated"])
def test_preannotate_refuses_a_bad_bundle_in_one_line_before_any_work(litert: None, tmp_path: Path, make,
                                                                      message: str,
                                                                      capsys: pytest.CaptureFixture[str]) -> None:
    session = Path(shutil.copytree(SESSION, tmp_path / SESSION.name, ignore=shutil.ignore_patterns("serial")))
    model = make(tmp_path)
    assert main(["preannotate", str(session), "--model", str(model)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert re.search(rf"--model {re.escape(str(model))}: " + message, err), err
    assert not (session / "machine").exists()
