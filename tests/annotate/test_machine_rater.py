"""The machine rater on real faces: our Face Landmarker against MediaPipe's own, and ``effortface preannotate``.

The faces are three official White House photographs (public domain, tests/data/faces/README.md)
framed into a 640 x 480 clip with faceless stretches (tests/annotate/face_clip.py). MediaPipe itself
(``mediapipe``, installed without its dependencies where available) is the reference; the parity
tests skip, saying why, where it cannot be imported.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
import signal
import subprocess
from pathlib import Path

import numpy as np
import pytest

from effortface.annotate.keyframes import KeyframeTrack, RaterAnnotations
from effortface.annotate.machine.landmarker import (ARKIT_NAMES, DEFAULT_MODEL, DEFAULT_MODEL_SHA256,
                                                    FaceLandmarker)
from effortface.annotate.machine.effort import session_weights
from effortface.annotate.machine.mapping import default_mapping, map_scores
from effortface.annotate.machine.preannotate import frame_times_ms, preannotate_session
from effortface.annotate.machine.track import (CSV_NAME, FOUR, MACHINE_DIR, SIDECAR_NAME, read_machine_track,
                                               write_machine_track)
from effortface.core.session.folder import read_session
from effortface.cli import main
from effortface.core.errors import SessionFormatError, UserError
from effortface.core.jobs import Cancelled

from ..capture_tool.capture_helpers import BODY, effortface, hxm_chunks, start_replay, write_serlog
from . import face_clip

#: the seven ARKit scores behind our four blendshapes
SEVEN = ("jawOpen", "mouthStretchLeft", "mouthStretchRight", "eyeSquintLeft", "eyeSquintRight",
         "browDownLeft", "browDownRight")
SEVEN_IDX = [ARKIT_NAMES.index(n) for n in SEVEN]


def _mediapipe():  # type: ignore[no-untyped-def]
    try:
        import mediapipe as mp
        from mediapipe.tasks.python import BaseOptions, vision
    except Exception as exc:  # ImportError, or a missing native library
        pytest.skip(f"MediaPipe's own FaceLandmarker (the reference) cannot be imported here: {exc}")
    return mp, BaseOptions, vision


def mediapipe_video(rgbs: list[np.ndarray], timestamps_ms: np.ndarray | None = None) -> list[np.ndarray | None]:
    """MediaPipe's FaceLandmarker in VIDEO mode on the frames: 52 scores per frame, None without a face."""
    ms = np.arange(len(rgbs)) * 33 if timestamps_ms is None else timestamps_ms
    mp, BaseOptions, vision = _mediapipe()
    options = vision.FaceLandmarkerOptions(base_options=BaseOptions(model_asset_path=str(DEFAULT_MODEL)),
                                           running_mode=vision.RunningMode.VIDEO, output_face_blendshapes=True,
                                           num_faces=1)
    landmarker = vision.FaceLandmarker.create_from_options(options)
    out: list[np.ndarray | None] = []
    try:
        for i, rgb in enumerate(rgbs):
            r = landmarker.detect_for_video(mp.Image(image_format=mp.ImageFormat.SRGB, data=np.ascontiguousarray(rgb)),
                                            int(ms[i]))
            out.append(np.array([c.score for c in r.face_blendshapes[0]]) if r.face_blendshapes else None)
    finally:
        landmarker.close()
    return out


def read_rgb(video: Path) -> list[np.ndarray]:
    """Every frame of a video, RGB."""
    import cv2

    cap = cv2.VideoCapture(str(video))
    frames = []
    while True:
        ok, bgr = cap.read()
        if not ok:
            break
        frames.append(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB))
    cap.release()
    return frames


def parity(face: np.ndarray, scores: np.ndarray, reference: list[np.ndarray | None]) -> dict[str, float]:
    """Face agreement on MediaPipe's face and no-face frames, and the seven scores' |differences|."""
    ref_face = np.array([r is not None for r in reference])
    both = face & ref_face
    diff = np.abs(np.array([reference[i][SEVEN_IDX] for i in np.flatnonzero(both)]) - scores[both][:, SEVEN_IDX])
    return {"agree_face": float(np.mean(face[ref_face])) if ref_face.any() else 1.0,
            "agree_blank": float(np.mean(~face[~ref_face])) if (~ref_face).any() else 1.0,
            "n_face": int(ref_face.sum()), "n_blank": int((~ref_face).sum()),
            "median": float(np.median(diff)), "p95": float(np.percentile(diff, 95))}


def assert_parity(p: dict[str, float]) -> None:
    assert p["n_face"] >= 50 and p["n_blank"] >= 10, p
    assert p["agree_face"] >= 0.97 and p["agree_blank"] >= 0.97, p
    assert p["median"] <= 0.03 and p["p95"] <= 0.15, p


@pytest.fixture(scope="module")
def clip(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[str | None]]:
    """The real-face clip as an MJPG AVI, and the photograph of each frame (None: no face)."""
    path = tmp_path_factory.mktemp("clip") / "faces.avi"
    return path, face_clip.write_clip(path)


# ----------------------------------------------------------------------------------- the model shipped
def test_the_shipped_bundle_is_mediapipes_with_its_licence() -> None:
    assert hashlib.sha256(DEFAULT_MODEL.read_bytes()).hexdigest() == DEFAULT_MODEL_SHA256
    data = DEFAULT_MODEL.parent
    assert "Apache License" in (data / "LICENSE-Apache-2.0.txt").read_text(encoding="utf-8")
    assert DEFAULT_MODEL_SHA256 in (data / "README.md").read_text(encoding="utf-8")


def test_the_real_faces_are_whole_and_documented() -> None:
    readme = (face_clip.FACES / "README.md").read_text(encoding="utf-8")
    names = sorted({n for n, _ in face_clip.SCRIPT if n is not None})
    assert len(names) == 3 and "public domain" in readme.lower()
    for name in names:
        digest = hashlib.sha256((face_clip.FACES / name).read_bytes()).hexdigest()
        assert f"| `{name}` | `{digest}` |" in readme, name


def test_a_file_that_is_not_a_bundle_is_one_line(tmp_path: Path) -> None:
    bad = tmp_path / "model.task"
    bad.write_bytes(b"not a zip")
    with pytest.raises(UserError, match=r"--model .*model.task: expected a Face Landmarker bundle \(a zip\)"):
        FaceLandmarker(bad)


# ----------------------------------------------------------------------------------- the engine
def test_our_landmarker_matches_mediapipe_video_mode_on_real_faces(clip) -> None:
    path, names = clip
    rgbs = read_rgb(path)
    assert len(rgbs) == len(names)
    reference = mediapipe_video(rgbs)
    ours = FaceLandmarker()
    results = [ours.process(rgb, i * 33) for i, rgb in enumerate(rgbs)]
    face = np.array([r.face for r in results])
    scores = np.array([r.scores if r.face else np.full(52, np.nan) for r in results])
    p = parity(face, scores, reference)
    assert_parity(p)
    assert p["median"] <= 0.005 and p["p95"] <= 0.02, p  # the same pipeline, smoothing included
    # and both see what the clip shows: a face on the photographs, none on the empty corner
    truth = np.array([n is not None for n in names])
    assert np.mean(face == truth) >= 0.97


def test_without_tracking_it_matches_mediapipe_image_mode_closely(clip) -> None:
    """The detector on every frame (:meth:`FaceLandmarker.reset` between frames) against IMAGE mode."""
    mp, BaseOptions, vision = _mediapipe()
    rgbs = read_rgb(clip[0])[::3]
    options = vision.FaceLandmarkerOptions(base_options=BaseOptions(model_asset_path=str(DEFAULT_MODEL)),
                                           running_mode=vision.RunningMode.IMAGE, output_face_blendshapes=True,
                                           num_faces=1)
    with vision.FaceLandmarker.create_from_options(options) as landmarker:
        reference = []
        for rgb in rgbs:
            r = landmarker.detect(mp.Image(image_format=mp.ImageFormat.SRGB, data=np.ascontiguousarray(rgb)))
            reference.append(np.array([c.score for c in r.face_blendshapes[0]]) if r.face_blendshapes else None)
    ours = FaceLandmarker()
    results = []
    for rgb in rgbs:
        ours.reset()
        results.append(ours.process(rgb))
    face = np.array([r.face for r in results])
    scores = np.array([r.scores if r.face else np.full(52, np.nan) for r in results])
    p = parity(face, scores, reference)
    assert p["agree_face"] == p["agree_blank"] == 1.0 and p["median"] <= 0.005 and p["p95"] <= 0.02, p


def test_a_frame_without_a_face_has_no_scores(clip) -> None:
    rgb = read_rgb(clip[0])[0]  # the clip opens on the empty corner of a photograph
    assert clip[1][0] is None
    result = FaceLandmarker().process(rgb)
    assert not result.face and result.scores is None and result.landmarks is None


def test_an_open_mouth_scores_higher_jaw_open_than_a_closed_one() -> None:
    import cv2

    def jaw_open(name: str) -> float:
        landmarker = FaceLandmarker()
        result = landmarker.process(cv2.cvtColor(face_clip.photo(name), cv2.COLOR_BGR2RGB))
        assert result.face and result.scores is not None, name
        return float(result.scores[ARKIT_NAMES.index("jawOpen")])

    opened, closed = jaw_open(face_clip.OPEN_MOUTH), jaw_open(face_clip.CLOSED_MOUTH)
    assert opened > closed + 0.2, (opened, closed)


# ----------------------------------------------------------------------------------- files
def _track_for(n: int, face: np.ndarray):  # type: ignore[no-untyped-def]
    from effortface.annotate.machine.track import MachineTrack

    rng = np.random.default_rng(1)
    scores = rng.uniform(0, 1, (n, 52))
    scores[~face] = np.nan
    weights = map_scores(scores, default_mapping(), FOUR)
    return MachineTrack(frame=np.arange(n), t_s=np.arange(n) / 30.0, face=face, weights=weights, scores=scores,
                        sidecar={"calibration": {"kind": "raw: no human key-frames"}})


def test_the_track_round_trips_and_refuses_to_replace(tmp_path: Path) -> None:
    face = np.array([True, False, True, True])
    track = _track_for(4, face)
    path = write_machine_track(tmp_path, track)
    assert path == tmp_path / MACHINE_DIR / CSV_NAME and (tmp_path / MACHINE_DIR / SIDECAR_NAME).is_file()
    lines = path.read_text().splitlines()
    assert lines[0].split(",")[:7] == ["frame", "t_s", "face", *FOUR] and lines[0].split(",")[7:] == list(ARKIT_NAMES)
    assert lines[2] == "1,0.0333,0" + "," * 56  # no face: every weight and score empty
    back = read_machine_track(tmp_path)
    assert back is not None
    assert np.array_equal(back.face, face) and np.array_equal(back.frame, track.frame)
    np.testing.assert_allclose(back.scores, track.scores, atol=1e-5)
    np.testing.assert_allclose(back.weights, track.weights, atol=1e-5)
    assert back.sidecar == track.sidecar
    before = path.read_bytes()
    with pytest.raises(UserError, match="use --force"):
        write_machine_track(tmp_path, _track_for(4, np.ones(4, bool)))
    assert path.read_bytes() == before
    write_machine_track(tmp_path, _track_for(4, np.ones(4, bool)), force=True)
    assert read_machine_track(tmp_path).face.all()


def test_no_track_is_none_and_a_damaged_one_names_the_file(tmp_path: Path) -> None:
    assert read_machine_track(tmp_path) is None
    path = write_machine_track(tmp_path, _track_for(3, np.ones(3, bool)))
    text = path.read_text().splitlines()
    path.write_text("\n".join([text[0], text[1], text[2].replace(",1,", ",x,", 1)]) + "\n")
    with pytest.raises(SessionFormatError, match=rf"{CSV_NAME}: line 3: column face: expected 1 or 0"):
        read_machine_track(tmp_path)
    path.write_bytes(b"frame,t_s\n")
    with pytest.raises(SessionFormatError, match=rf"{CSV_NAME}: expected header"):
        read_machine_track(tmp_path)


# ----------------------------------------------------------------------------------- Must show
@pytest.fixture(scope="module")
def recorded(clip, shared_data: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A session recorded by ``effortface capture --video`` from the real-face clip (a replayed strap)."""
    tmp = tmp_path_factory.mktemp("capture")
    replay, pty = start_replay(write_serlog(tmp / "strap.serlog", hxm_chunks(shared_data, 0, 60)), "--speed", "4")
    cap = subprocess.Popen(effortface("capture", "--port", pty, "--protocol", "hxm", "--participant", "P07", *BODY,
                                      "--video", clip[0], "--duration", "5.2", "--out", tmp / "lab"),
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    out, err = cap.communicate(timeout=120)
    replay.send_signal(signal.SIGTERM)
    replay.wait(10)
    assert cap.returncode == 0, err
    session = Path(out.splitlines()[0])
    assert read_session(session).info.complete and len(read_session(session).frame_times_s) >= 100, err
    return session


def _copy(session: Path, tmp_path: Path) -> Path:
    dst = tmp_path / session.parent.name / session.name
    shutil.copytree(session, dst)
    return dst


def test_preannotate_a_captured_real_face_session_matches_mediapipe(recorded: Path, tmp_path: Path, capsys) -> None:
    session = _copy(recorded, tmp_path)
    assert main(["preannotate", str(session)]) == 0
    out, err = capsys.readouterr()
    assert f"wrote {session / MACHINE_DIR / CSV_NAME}" in out
    # stderr is not a terminal here: plain progress lines a log can hold, no carriage returns
    assert "\r" not in err and "\x1b" not in err and f"{session.name[:32]}: 100% frames rated" in err
    track = read_machine_track(session)
    times = read_session(session).frame_times_s
    assert track is not None and len(track.frame) == len(times)  # one row per recorded frame
    assert np.array_equal(track.frame, np.arange(len(times)))
    np.testing.assert_allclose(track.t_s, times, atol=5e-5)
    assert np.isnan(track.weights[~track.face]).all() and np.isnan(track.scores[~track.face]).all()
    assert not np.isnan(track.weights[track.face]).any()
    reference = mediapipe_video(read_rgb(session / "video.avi"), frame_times_ms(times))  # the same timestamps
    assert_parity(parity(track.face, track.scores, reference))
    side = track.sidecar
    assert side["model"]["sha256"] == DEFAULT_MODEL_SHA256 and side["calibration"]["kind"] == "raw: no human key-frames"
    assert side["frames_without_face"] == int((~track.face).sum()) > 0 and side["time_taken_s"] > 0
    # raw mapping: the effort mapping of the 52 scores (no keys: nothing learned), sidecar format 2
    np.testing.assert_allclose(track.weights, session_weights(session, track.scores, track.t_s)[0], atol=2e-5)
    assert side["format_version"] == 2 and side["mapping"]["kind"] == "effort v2"


def test_calibration_is_fitted_on_the_human_keys(recorded: Path, tmp_path: Path) -> None:
    session = _copy(recorded, tmp_path)
    preannotate_session(session)
    raw = read_machine_track(session)
    keyed = np.flatnonzero(raw.face)[::4]
    (session / "annotations").mkdir(exist_ok=True)
    # a rater whose scale is the machine's raw jawOpen squared and doubled (monotone), clipped
    human = np.clip(2 * raw.weights[keyed, 1] ** 2 + 0.1, 0, 1)
    track = KeyframeTrack()
    for f, w in zip(keyed, human):
        track.add(int(f), float(w))
    RaterAnnotations("R1", session.name, tracks={"mouth_open": track}).save(session / "annotations" / "R1.json")
    preannotate_session(session, force=True)
    calibrated = read_machine_track(session)
    report = calibrated.sidecar["calibration"]
    assert report["kind"] == "isotonic per participant" and report["participant"] == "P07"
    mouth = report["blendshapes"]["mouth_open"]
    assert mouth["kind"] == "isotonic" and mouth["n_keys"] == len(keyed) and mouth["fit_mae"] < 0.02
    assert mouth["heldout_mae"] is not None and mouth["heldout_mae"] < 0.1
    assert report["blendshapes"]["eye_squint"]["kind"].startswith("raw")
    np.testing.assert_allclose(calibrated.weights[keyed, 1], human, atol=0.03)
    np.testing.assert_allclose(calibrated.weights[:, 2], raw.weights[:, 2], atol=1e-6, equal_nan=True)


def test_a_cancel_writes_nothing(recorded: Path, tmp_path: Path) -> None:
    session = _copy(recorded, tmp_path)
    calls = []
    with pytest.raises(Cancelled):
        preannotate_session(session, progress=lambda done, total: calls.append((done, total)),
                            cancel=lambda: len(calls) >= 10)
    assert calls[-1] == (10, len(read_session(session).frame_times_s))
    assert not (session / MACHINE_DIR / CSV_NAME).exists()


def test_two_sessions_in_parallel_equal_one_after_the_other(recorded: Path, tmp_path: Path) -> None:
    a, b = _copy(recorded, tmp_path / "a"), _copy(recorded, tmp_path / "b")
    assert main(["preannotate", str(a), str(b), "--workers", "2"]) == 0
    serial = _copy(recorded, tmp_path / "c")
    assert main(["preannotate", str(serial)]) == 0
    expected = read_machine_track(serial)
    for folder in (a, b):  # one interpreter thread per worker, two for the serial run: the same ratings
        got = read_machine_track(folder)
        assert np.array_equal(got.face, expected.face) and np.array_equal(got.frame, expected.frame)
        np.testing.assert_allclose(got.scores, expected.scores, atol=1e-4)
        assert got.sidecar["interpreter_threads"] == max(1, (os.cpu_count() or 1) // 2)


def _no_video(s: Path) -> None:
    (s / "video.avi").unlink()


def _damaged_video(s: Path) -> None:
    (s / "video.avi").write_bytes(np.random.default_rng(0).bytes(50_000))


def _incomplete(s: Path) -> None:
    doc = json.loads((s / "session.json").read_text())
    doc["complete"] = False
    (s / "session.json").write_text(json.dumps(doc))


def _rated(s: Path) -> None:
    (s / MACHINE_DIR).mkdir()
    (s / MACHINE_DIR / CSV_NAME).write_text("earlier rating\n")


@pytest.mark.parametrize(("spoil", "expected"), [
    (_no_video, r"video.avi: expected the session's video, found nothing"),
    (_damaged_video, r"video_frames.csv: expected one row per frame of video.avi \(0 frames\)"),
    (_incomplete, r"session.json: expected a complete session, found complete is false \(run 'effortface recover"),
    (_rated, r"face_landmarker.csv: expected no machine rating yet, found one exists \(use --force"),
], ids=["no video", "damaged video", "incomplete", "already rated"])
def test_a_session_it_cannot_rate_is_one_line_exit_2(recorded: Path, tmp_path: Path, capfd, spoil, expected) -> None:
    session = _copy(recorded, tmp_path)
    spoil(session)
    before = sorted(p.name for p in session.rglob("*"))
    assert main(["preannotate", str(session)]) == 2
    err = capfd.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("effortface preannotate: error: "), err
    assert __import__("re").search(expected, err[0]), err[0]
    assert sorted(p.name for p in session.rglob("*")) == before  # nothing written


def test_a_video_damaged_after_its_first_frames_is_one_line_and_writes_nothing(recorded: Path, tmp_path: Path,
                                                                              capfd) -> None:
    session = _copy(recorded, tmp_path)
    data = bytearray((session / "video.avi").read_bytes())
    start = len(data) // 3
    data[start:start + len(data) // 3] = bytes(len(data) // 3)  # a third of the file zeroed
    (session / "video.avi").write_bytes(bytes(data))
    code = main(["preannotate", str(session)])
    err = [line for line in capfd.readouterr().err.splitlines() if "error" in line]  # the bar aside
    assert code == 2 and len(err) == 1 and err[0].startswith("effortface preannotate: error: "), err
    assert "video.avi: expected" in err[0] and "does not decode (a damaged video)" in err[0], err[0]
    assert not (session / MACHINE_DIR / CSV_NAME).exists()


def test_a_session_being_recorded_is_refused(recorded: Path, tmp_path: Path, capfd) -> None:
    from effortface.core.session.folder import RECORDING_LOCK
    from effortface.core.locks import acquire_lock

    session = _copy(recorded, tmp_path)
    with acquire_lock(session / RECORDING_LOCK, "capture"):  # as a running capture holds it
        assert main(["preannotate", str(session)]) == 2
    err = capfd.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "expected a session no capture is recording (to pre-annotate it)" in err[0], err
    assert not (session / MACHINE_DIR).exists()


def test_ctrl_c_leaves_nothing_half_written(tmp_path: Path) -> None:
    """Interrupted while rating a sample-lab session (hundreds of frames): exit 130, no file, no temp file."""
    samples = Path(__file__).resolve().parents[2] / "sample_sessions"
    source = next(p for p in sorted(samples.iterdir()) if (p / "video.avi").is_file())
    session = _copy(source, tmp_path)
    proc = subprocess.Popen(effortface("preannotate", session), stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    seen = b""
    # frames rated, not only loading (stderr is a pipe: plain progress lines, each tenth of the frames)
    while not re.search(rb": +[1-9][0-9]*% frames rated", seen) and proc.poll() is None:
        seen += proc.stderr.read1(4096)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, (seen + err).decode()[-2000:]
    assert "effortface preannotate: interrupted" in err.decode()
    assert not (session / MACHINE_DIR).exists() or not any((session / MACHINE_DIR).iterdir())


def test_force_replaces_an_earlier_rating(recorded: Path, tmp_path: Path) -> None:
    session = _copy(recorded, tmp_path)
    _rated(session)
    assert main(["preannotate", str(session), "--force"]) == 0
    assert read_machine_track(session) is not None


def test_bad_options_are_one_line(recorded: Path, tmp_path: Path, capfd) -> None:
    assert main(["preannotate", str(recorded), "--workers", "0"]) == 2
    assert "--workers: expected a whole number of at least 1, found 0" in capfd.readouterr().err
    assert main(["preannotate", str(recorded), "--model", str(tmp_path / "none.task")]) == 2
    assert "none.task: expected a face_landmarker.task file, found nothing" in capfd.readouterr().err
    assert main(["preannotate", str(tmp_path)]) == 2
    assert "expected a session folder (with session.json)" in capfd.readouterr().err
