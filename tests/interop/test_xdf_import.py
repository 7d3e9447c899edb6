"""``effortface import xdf`` (Must show): an XDF file written here from a sample session's strap,
events, work and frame times (pyxdf reads it) imports to a session that trains with the sample
lab's other sessions; missing and ambiguous streams are one-line errors."""

from __future__ import annotations

import dataclasses

import csv
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from effortface.synth.work import derive_work, write_work

from effortface.annotate.keyframes import read_annotations

from effortface.core.session.folder import read_session
from effortface.train.dataset import session_table

from .xdf_writer import XdfStream, write_xdf

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "sample_sessions"
SESSION = "P06_20260121-125500_cardio"
LSL_T0 = 5000.0   # the recording's LSL clock at the session's time 0


def _effortface(*args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "effortface", *map(str, args)], capture_output=True, text=True,
                          timeout=600)


def _rows(path: Path) -> list[dict]:
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def session_streams(folder: Path) -> list[XdfStream]:
    """The session's files as the LSL streams a LabRecorder would have recorded."""
    hr_stamps, hr_values = [], []
    for r in _rows(folder / "heart_rate.csv"):
        hr = float(r["hr_bpm"]) if r["valid"] == "1" and r["hr_bpm"] else float("nan")
        for rr in (r["rr_ms"].split() or ["nan"]):
            hr_stamps.append(LSL_T0 + float(r["t_s"]))
            hr_values.append([hr, float(rr)])
    events = _rows(folder / "events.csv")
    # the lab's work as `effortface work` derives it (the sample lab keeps no work.csv, as a capture)
    work = [{"t_s": t, "w_per_kg": w, "p_per_kg": p} for t, w, p in
            zip(*(lambda d: (d.t_s, d.w_per_kg, d.p_per_kg))(derive_work(folder))) if np.isfinite(w)]
    frames = _rows(folder / "video_frames.csv")
    return [
        XdfStream("Polar H10 P06", "HeartRate", [("hr_bpm", "bpm"), ("rr_ms", "ms")], hr_stamps, hr_values),
        XdfStream("effortface events", "Markers", [("event", "")], [LSL_T0 + float(e["t_s"]) for e in events],
                  [[json.dumps({"kind": e["kind"], "label": e["label"], "value": e["value"]})] for e in events],
                  fmt="string"),
        XdfStream("effort", "EffortWork", [("w_per_kg", "W/kg"), ("p_per_kg", "W/kg")],
                  [LSL_T0 + float(w["t_s"]) for w in work],
                  [[float(w["w_per_kg"]), float(w["p_per_kg"])] for w in work], srate_hz=1.0),
        XdfStream("camera frames", "VideoFrames", [("frame", "")], [LSL_T0 + float(f["t_s"]) for f in frames],
                  [[float(f["frame"])] for f in frames]),
        XdfStream("EEG", "EEG", [("Cz", "uV")], [LSL_T0 + k / 10 for k in range(50)], [[0.0]] * 50, srate_hz=10),
    ]


@pytest.fixture(scope="module")
def imported(tmp_path_factory) -> tuple[Path, Path]:
    """A copy of the sample lab where P06's cardio session comes from an XDF import."""
    tmp = tmp_path_factory.mktemp("xdf")
    lab = tmp / "lab"
    shutil.copytree(SAMPLE, lab, ignore=shutil.ignore_patterns("_ground_truth", "reliability", "simlab", "*.py",
                                                               "*.md", "serial"))
    original = lab / SESSION
    write_work(original)  # the original's work.csv, made by the product, to compare the import with
    xdf = write_xdf(tmp / "rec.xdf", session_streams(original))
    shutil.move(str(original), tmp / SESSION)
    info = read_session(tmp / SESSION).participant
    out = _effortface("import", "xdf", xdf, "--out", lab, "--participant", "P06", "--sex", info.sex,
                      "--age", info.age, "--height", info.height_m, "--mass", info.mass_kg,
                      "--training-level", info.training_level, "--label", "cardio",
                      "--video", tmp / SESSION / "video.avi", "--video-stream", "camera frames")
    assert out.returncode == 0, out.stderr
    folder = Path(out.stdout.strip())
    # the raters' work, re-saved for the imported session by the product's writer (an annotation
    # file names its session: one copied from another session is refused by train, issue 17)
    (folder / "annotations").mkdir()
    for path in sorted((tmp / SESSION / "annotations").glob("*.json")):
        keys = read_annotations(path)
        dataclasses.replace(keys, session_id=folder.name).save(folder / "annotations" / path.name)
    return folder, tmp / SESSION


def test_imported_session_matches_the_original(imported):
    folder, original = imported
    for name in ("heart_rate.csv", "events.csv", "video_frames.csv", "work.csv"):
        got, want = _rows(folder / name), _rows(original / name)
        assert len(got) == len(want), name
        key = "t_s"
        np.testing.assert_allclose([float(r[key]) for r in got], [float(r[key]) for r in want], atol=2e-3)
    hr_got, hr_want = _rows(folder / "heart_rate.csv"), _rows(original / "heart_rate.csv")
    # the same rows without a heart rate (contact lost: empty hr_bpm), the same heart rates elsewhere
    # (compared apart: pytest.approx does not compare an empty string under every pytest it admits)
    assert [r["hr_bpm"] == "" for r in hr_got] == [r["hr_bpm"] == "" for r in hr_want]
    assert [float(r["hr_bpm"]) for r in hr_got if r["hr_bpm"]] == \
        pytest.approx([float(r["hr_bpm"]) for r in hr_want if r["hr_bpm"]], rel=1e-6)
    for got, want in zip(hr_got, hr_want):    # R-R intervals travel as float32
        assert [float(v) for v in got["rr_ms"].split()] == pytest.approx([float(v) for v in want["rr_ms"].split()],
                                                                         rel=1e-6)
    assert [(r["kind"], r["label"]) for r in _rows(folder / "events.csv")] == \
        [(r["kind"], r["label"]) for r in _rows(original / "events.csv")]
    info = read_session(folder).info
    assert info.complete and info.extra["lsl"]["clock_offset_s"] == pytest.approx(LSL_T0, abs=0.2)
    table_got, table_want = session_table(folder), session_table(original)
    np.testing.assert_allclose(table_got["hr_bpm"], table_want["hr_bpm"], atol=0.5, equal_nan=True)


def test_imported_session_trains_with_the_lab(imported, tmp_path):
    folder, _ = imported
    out = _effortface("train", folder.parent, "--out", tmp_path / "model", "--max-rows", "40")
    assert out.returncode == 0, out.stderr
    doc = json.loads((tmp_path / "model" / "model.json").read_text())
    assert "P06" in doc["provenance"]["participants"]
    assert doc["provenance"]["n_sessions"] == 12     # 11 sample sessions + the imported one (the original moved out)


@pytest.mark.parametrize(("streams", "args", "match"), [
    (lambda s: [x for x in s if x.type != "HeartRate"], [],
     "expected a heart-rate stream (named or typed HeartRate, HR or RR, or a channel labelled so or in bpm; "
     "or name one with --hr-stream), found 'effortface events' (Markers)"),
    (lambda s: s + [XdfStream("Polar 2", "HeartRate", [("hr_bpm", "bpm")], [1.0], [[60.0]])], [],
     "expected one heart-rate stream, found 2: 'Polar H10 P06' (HeartRate), 'Polar 2' "
     "(HeartRate) (choose one by name with --hr-stream)"),
    (lambda s: s, ["--hr-stream", "Garmin"], "expected a stream named or typed 'Garmin' (--hr-stream)"),
    (lambda s: s, ["--video", "nofile.avi"], "--video nofile.avi: expected a video file, found no such file"),
])
def test_missing_or_ambiguous_streams_are_one_line(tmp_path, streams, args, match):
    xdf = write_xdf(tmp_path / "r.xdf", streams(session_streams(SAMPLE / SESSION)))
    out = _effortface("import", "xdf", xdf, "--out", tmp_path / "s", "--participant", "P06", *args)
    assert out.returncode == 2 and match in out.stderr, out.stderr
    assert len(out.stderr.strip().splitlines()) == 1 and not (tmp_path / "s").exists()


def test_not_an_xdf_file(tmp_path):
    (tmp_path / "bad.xdf").write_bytes(b"nope")
    out = _effortface("import", "xdf", tmp_path / "bad.xdf", "--out", tmp_path / "s", "--participant", "P06")
    assert out.returncode == 2 and "bad.xdf: expected an XDF file" in out.stderr


def test_mocap_stream_becomes_motion_csv(tmp_path, shared_data):
    """The stream becomes motion/mocap.csv, attached at its own time (motion.json), so `effortface work`
    derives the session's work from it with nothing else to do."""
    from effortface.synth.motion import read_motion
    from effortface.synth.work import read_motion_index

    clip = read_motion(shared_data / "motion/cmu_13_29_squats_120fps.bvh").slice_s(0, 5)
    labels = [(f"{j}_{a}", "m") for j in clip.joint_names for a in "xyz"]
    stamps = [LSL_T0 + 30.0 + t for t in clip.t_s]  # the take starts 30 s into the recording
    mocap = XdfStream("Vicon", "MoCap", labels, stamps, clip.positions_m.reshape(clip.n_frames, -1).tolist(),
                      srate_hz=clip.fps)
    streams = [s for s in session_streams(SAMPLE / SESSION) if s.type == "HeartRate"] + [mocap]
    xdf = write_xdf(tmp_path / "m.xdf", streams)
    out = _effortface("import", "xdf", xdf, "--out", tmp_path / "s", "--participant", "P06", "--mocap-stream", "Vicon",
                      "--mass", "70", "--sex", "male")
    assert out.returncode == 0, out.stderr
    assert out.stderr.strip() == (f"effortface import: note: mocap stream 'Vicon': skeleton tree none in the stream: "
                                  f"{clip.joint_names[0]} taken as the parent of every other joint "
                                  "(--mocap-skeleton FILE gives the real one)")
    session = Path(out.stdout.strip())
    motion = read_motion(session / "motion" / "mocap.csv")
    assert motion.joint_names == clip.joint_names and motion.fps == pytest.approx(clip.fps, rel=1e-3)
    np.testing.assert_allclose(motion.positions_m, clip.positions_m, atol=1e-5)   # float32 in the XDF
    (entry,) = read_motion_index(session / "motion" / "motion.json")
    clock_offset_s = json.loads((session / "session.json").read_text())["lsl"]["clock_offset_s"]
    assert entry["path"] == "mocap.csv" and entry["aligned"] == "offset"
    assert entry["offset_s"] == pytest.approx(LSL_T0 + 30.0 - clock_offset_s, abs=1e-3)
    assert entry["duration_s"] == pytest.approx(5.0, abs=0.02)
    work = _effortface("work", session)
    assert work.returncode == 0, work.stderr
    rows = np.genfromtxt(session / "work.csv", delimiter=",", names=True)
    during = (rows["t_s"] >= entry["offset_s"]) & (rows["t_s"] <= entry["offset_s"] + 5.0)
    assert during.any() and np.nanmax(rows["w_per_kg"][during]) > 0  # the squats' work, at their time


def test_a_mocap_skeleton_gives_the_clips_tree(tmp_path, shared_data):
    """--mocap-skeleton: the tree travels with the clip into motion/; joints not the stream's, or the
    option without --mocap-stream, are one line each (exit 2, nothing written)."""
    from effortface.synth.motion import read_motion

    clip = read_motion(shared_data / "motion/cmu_13_29_squats_120fps.bvh").slice_s(0, 1)
    labels = [(f"{j}_{a}", "m") for j in clip.joint_names for a in "xyz"]
    mocap = XdfStream("Vicon", "MoCap", labels, [LSL_T0 + t for t in clip.t_s],
                      clip.positions_m.reshape(clip.n_frames, -1).tolist(), srate_hz=clip.fps)
    xdf = write_xdf(tmp_path / "m.xdf", [s for s in session_streams(SAMPLE / SESSION) if s.type == "HeartRate"]
                    + [mocap])
    tree = tmp_path / "tree.json"
    tree.write_text(json.dumps({"joints": list(clip.joint_names), "parents": [int(p) for p in clip.parents]}))
    base = ["import", "xdf", xdf, "--out", tmp_path / "s", "--participant", "P06", "--mocap-stream", "Vicon"]
    out = _effortface(*base, "--mocap-skeleton", tree)
    assert out.returncode == 0 and out.stderr == "", out.stderr
    session = Path(out.stdout.strip())
    assert read_motion(session / "motion" / "mocap.csv").parents.tolist() == [int(p) for p in clip.parents]
    assert json.loads((session / "session.json").read_text())["lsl"]["mocap_skeleton"] == "--mocap-skeleton tree.json"
    wrong = tmp_path / "wrong.json"
    wrong.write_text(json.dumps({"joints": list(clip.joint_names[::-1]), "parents": [-1] * len(clip.joint_names)}))
    backwards = tmp_path / "backwards.json"  # a parent listed after its child
    backwards.write_text(json.dumps({"joints": list(clip.joint_names),
                                     "parents": [1] + [-1] * (len(clip.joint_names) - 1)}))
    for extra, expected in (
            (["--mocap-skeleton", backwards], f"--mocap-skeleton {backwards}"),
            (["--mocap-skeleton", wrong], f"--mocap-skeleton {wrong}: expected the {len(clip.joint_names)} joints of mocap "
                                          f"stream 'Vicon' in its channel order"),
            (["--mocap-skeleton", tmp_path / "none.json"], f"{tmp_path / 'none.json'}: expected a skeleton file")):
        bad = _effortface(*base[:3], "--out", tmp_path / "bad", *base[5:], *extra)
        assert bad.returncode == 2 and bad.stderr.count("\n") == 1 and expected in bad.stderr, bad.stderr
        assert ".import-" not in bad.stderr  # never the staging copy's name
    assert not (tmp_path / "bad").exists() or not any((tmp_path / "bad").iterdir())
    alone = _effortface("import", "xdf", xdf, "--out", tmp_path / "bad", "--participant", "P06",
                        "--mocap-skeleton", tree)
    assert alone.returncode == 2 and "--mocap-skeleton: expected with --mocap-stream, found without it" in alone.stderr


def test_a_mocap_stream_that_is_no_body_is_one_line_and_writes_nothing(tmp_path):
    """Markers no segment can be found for: refused in one line naming the XDF and the stream."""
    labels = [(f"M{k:02d}_{a}", "m") for k in range(5) for a in "xyz"]
    stamps = [LSL_T0 + k / 100 for k in range(200)]
    values = [[0.1 * k, 0.0, 1.0 + 0.01 * (f % 7)] for f in range(200) for k in range(5)]
    mocap = XdfStream("Markers3D", "MoCap", labels, stamps,
                      [sum(values[f * 5:(f + 1) * 5], []) for f in range(200)], srate_hz=100.0)
    streams = [s for s in session_streams(SAMPLE / SESSION) if s.type == "HeartRate"] + [mocap]
    xdf = write_xdf(tmp_path / "m.xdf", streams)
    out = _effortface("import", "xdf", xdf, "--out", tmp_path / "s", "--participant", "P06",
                      "--mocap-stream", "Markers3D")
    assert out.returncode == 2 and "Traceback" not in out.stderr
    (line,) = out.stderr.strip().splitlines()
    assert line.startswith(f"effortface import: error: {xdf}: mocap stream 'Markers3D'") and "expected" in line, line
    assert not (tmp_path / "s").exists() or not any((tmp_path / "s").iterdir())
