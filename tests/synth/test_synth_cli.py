"""``effortface synth``: CSV and Live Link Face output on a real clip, refusals, bad input (exit 2)."""

from __future__ import annotations

import csv
import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from effortface.cli import main
from effortface.synth.bundle import write_bundle
from effortface.synth.curves_io import LIVELINK_BLENDSHAPES, livelink_timecode
from effortface.synth.face import jitter
from effortface.core.blendshapes import DEFAULT_SET

ROOT = Path(__file__).resolve().parents[2]
JJ = "motion/cmu_13_29_jumping_jacks_120fps.bvh"
COLUMNS = ["t_s", "w_per_kg", "p_per_kg", "nhr", "hr_bpm", "vo2", "resp_rate", "epoc",
           "mouth_stretch", "mouth_open", "eye_squint", "brow_lower"]


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as f:
        return list(csv.DictReader(f))


def test_synth_default_model_end_to_end(shared_data: Path, tmp_path: Path) -> None:
    """The documented command, run as a real process."""
    out = tmp_path / "x.csv"
    done = subprocess.run([sys.executable, "-m", "effortface", "synth", "default",
                           str(shared_data / JJ), "--out", str(out)],
                          cwd=ROOT, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    rows = _rows(out)
    assert list(rows[0]) == COLUMNS and len(rows) == 439
    # issue 16, 14: it says what it wrote and the clip's duration (it printed nothing before)
    wrote, read = done.stdout.splitlines()
    assert wrote == f"wrote {out}: 439 frames, 3.65 s of motion, units in {tmp_path / 'x.units.json'}"
    # issue 34: and how it read the clip (CMU cgspeed unit, Y up, the standing height)
    assert read.startswith(f"read {shared_data / JJ}: unit 0.05644 m (rest pose 27.46 units along x -> CMU "
                           "cgspeed unit (0.05644 m)), up y (gravity over the clip: the head above the feet")
    assert read.endswith("standing height 1.57 m")
    reading = json.loads((tmp_path / "x.units.json").read_text())["reading"]
    assert reading["unit_m"] == 0.05644 and reading["up_axis"] == "y"
    assert 1.5 < reading["body"]["height_m"] < 1.65 and not reading["body"]["trusted"]
    t = np.array([float(r["t_s"]) for r in rows])
    np.testing.assert_allclose(np.diff(t), 1 / 120, atol=1e-8)
    assert max(float(r["eye_squint"]) for r in rows) > 0.3


def test_synth_character_options_and_bundle(shared_data: Path, tmp_path: Path, make_bundle) -> None:
    model_dir = write_bundle(make_bundle(), tmp_path / "model")
    plain, loaded = tmp_path / "plain.csv", tmp_path / "loaded.csv"
    common = ["synth", str(model_dir), str(shared_data / JJ), "--age", "45", "--sex", "female",
              "--height", "1.65", "--mass", "60", "--training-level", "2"]
    assert main(common + ["--out", str(plain)]) == 0
    assert main(common + ["--out", str(loaded), "--load-left", "10", "--load-right", "10",
                          "--expressiveness", "1,1,0,1"]) == 0
    a, b = _rows(plain), _rows(loaded)
    assert float(b[-1]["w_per_kg"]) > float(a[-1]["w_per_kg"])
    assert all(float(r["eye_squint"]) == 0 for r in b)
    assert float(a[0]["hr_bpm"]) == pytest.approx(78.2)  # chart: female 36-45, TL 2: 3/5 of
    # the way from below average (79-84, mid 81.5) to average (74-78, mid 76) = 78.2 bpm


def test_unit_m_overrides_the_detected_bvh_unit(shared_data: Path, tmp_path: Path) -> None:
    """--unit-m 0.05644 equals CMU's detected unit; a larger unit makes a larger, harder-working body."""
    out = {name: tmp_path / f"{name}.csv" for name in ("auto", "cmu", "big")}
    clip = str(shared_data / JJ)
    assert main(["synth", "default", clip, "--out", str(out["auto"])]) == 0
    assert main(["synth", "default", clip, "--out", str(out["cmu"]), "--unit-m", "0.05644"]) == 0
    assert main(["synth", "default", clip, "--out", str(out["big"]), "--unit-m", "0.07"]) == 0
    auto, cmu, big = (_rows(out[k]) for k in ("auto", "cmu", "big"))
    assert auto == cmu
    w_auto = np.mean([float(r["w_per_kg"]) for r in auto])
    assert np.mean([float(r["w_per_kg"]) for r in big]) > 1.2 * w_auto


def test_livelink_output(shared_data: Path, tmp_path: Path) -> None:
    out = tmp_path / "take.csv"
    assert main(["synth", "default", str(shared_data / JJ), "--out", str(out),
                 "--format", "livelink", "--every-frame"]) == 0
    with out.open(newline="") as f:
        reader = csv.reader(f)
        header = next(reader)
        rows = list(reader)
    assert header[:4] == ["Timecode", "BlendShapeCount", "EyeBlinkLeft", "EyeLookDownLeft"]
    assert len(LIVELINK_BLENDSHAPES) == 52 and header[2:54] == list(LIVELINK_BLENDSHAPES)
    assert header[54:] == ["HeadYaw", "HeadPitch", "HeadRoll", "LeftEyeYaw", "LeftEyePitch",
                           "LeftEyeRoll", "RightEyeYaw", "RightEyePitch", "RightEyeRoll"]
    assert len(rows) == 439 and all(r[1] == "61" and len(r) == 63 for r in rows)
    values = {name: np.array([float(r[i]) for r in rows]) for i, name in enumerate(header) if i > 1}
    plain = tmp_path / "plain.csv"
    main(["synth", "default", str(shared_data / JJ), "--out", str(plain)])
    squint = np.array([float(r["eye_squint"]) for r in _rows(plain)])
    np.testing.assert_allclose(values["EyeSquintLeft"], squint, atol=1e-6)
    np.testing.assert_allclose(values["EyeSquintRight"], squint, atol=1e-6)
    assert values["JawOpen"].max() >= 0 and values["EyeBlinkLeft"].max() == 0
    assert rows[0][0] == "00:00:00:00.000" and rows[1][0] == "00:00:00:00.500"
    # the default: one row per frame of the CSV's 60 fps timecode, the curves resampled
    resampled = tmp_path / "take60.csv"
    assert main(["synth", "default", str(shared_data / JJ), "--out", str(resampled), "--format", "livelink"]) == 0
    with resampled.open(newline="") as f:
        rows60 = list(csv.reader(f))[1:]
    assert len(rows60) == int(np.floor((len(rows) - 1) / 120 * 60)) + 1
    assert [r[0] for r in rows60[:3]] == ["00:00:00:00.000", "00:00:00:01.000", "00:00:00:02.000"]
    assert rows60[60][0] == "00:00:01:00.000"
    t = np.arange(len(rows)) / 120
    at60 = np.interp(np.arange(len(rows60)) / 60, t, values["EyeSquintLeft"])
    np.testing.assert_allclose([float(r[header.index("EyeSquintLeft")]) for r in rows60], at60, atol=1e-6)


def test_timecode() -> None:
    assert livelink_timecode(0.0) == "00:00:00:00.000"
    assert livelink_timecode(1 / 60) == "00:00:00:01.000"
    assert livelink_timecode(3725.5) == "01:02:05:30.000"


def test_refuses_to_overwrite(shared_data: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "x.csv"
    out.write_text("keep me\n")
    assert main(["synth", "default", str(shared_data / JJ), "--out", str(out)]) == 2
    assert "use --force" in capsys.readouterr().err
    assert out.read_text() == "keep me\n"
    assert main(["synth", "default", str(shared_data / JJ), "--out", str(out), "--force"]) == 0
    assert out.read_text().startswith("t_s,")


def test_units_sidecar(shared_data: Path, tmp_path: Path) -> None:
    """vo2, resp_rate and epoc have their units in ``<name>.units.json``; the CSV header is unchanged."""
    out = tmp_path / "face.csv"
    assert main(["synth", "default", str(shared_data / JJ), "--out", str(out)]) == 0
    assert out.read_text().splitlines()[0] == ",".join(COLUMNS)
    units = json.loads((tmp_path / "face.units.json").read_text())["units"]
    assert list(units) == COLUMNS
    assert (units["vo2"], units["resp_rate"], units["epoc"]) == ("ml/kg/min", "breaths/min", "ml/kg")
    assert units["hr_bpm"] == "beats/min" and units["mouth_open"].startswith("1 ")


def test_existing_units_sidecar_is_not_overwritten(shared_data: Path, tmp_path: Path, capsys) -> None:
    out, sidecar = tmp_path / "face.csv", tmp_path / "face.units.json"
    sidecar.write_text("mine\n")
    assert main(["synth", "default", str(shared_data / JJ), "--out", str(out)]) == 2
    assert f"found an existing {sidecar} (use --force" in capsys.readouterr().err
    assert sidecar.read_text() == "mine\n" and not out.exists()


def test_livelink_has_no_sidecar(shared_data: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "face.csv"
    assert main(["synth", "default", str(shared_data / JJ), "--out", str(out), "--format", "livelink"]) == 0
    assert capsys.readouterr().out.startswith(f"wrote {out}: 439 frames, 3.65 s of motion\n")
    assert not (tmp_path / "face.units.json").exists()


def _malformed_bvh(shared_data: Path, tmp_path: Path) -> Path:
    lines = (shared_data / JJ).read_text().splitlines()
    lines[190] = lines[190].replace(lines[190].split()[3], "1.2.3", 1)  # file line 191
    bad = tmp_path / "bad.bvh"
    bad.write_text("\n".join(lines) + "\n")
    return bad


def _unknown_joints_bvh(shared_data: Path, tmp_path: Path) -> Path:
    text = (shared_data / JJ).read_text()
    for old in ("LeftUpLeg", "LeftLeg", "LeftFoot"):
        text = text.replace(f"JOINT {old}\n", f"JOINT Bone_{old.lower()}_x\n")
    bad = tmp_path / "odd.bvh"
    bad.write_text(text)
    return bad


BAD_CLI = {
    r"bad\.bvh.*line 191": lambda d, t: [str(_malformed_bvh(d, t))],
    r"skeleton joints: .*unmapped segments: .*left_thigh": lambda d, t: [str(_unknown_joints_bvh(d, t))],
    r"character options: mass_kg: expected a number from 15 to 300 kg": lambda d, t: [str(d / JJ), "--mass", "-75"],
    r"character options: training_level: expected a number from 0 to 10, found 12":
        lambda d, t: [str(d / JJ), "--training-level", "12"],
    r"character options: expressiveness: expected 4 values": lambda d, t: [str(d / JJ), "--expressiveness", "1,1,1"],
    r"--expressiveness: expected 4 comma-separated numbers, found 'a,b'":
        lambda d, t: [str(d / JJ), "--expressiveness", "a,b"],
    r"character options: sex: expected one of female, male": lambda d, t: [str(d / JJ), "--sex", "x"],
    r"character options: load_back_kg: expected a load of 0 kg or more":
        lambda d, t: [str(d / JJ), "--load-back", "-1"],
    r"--filter-tau-s: filter_tau_s: expected time constants of 0 s or more, found -0.5":
        lambda d, t: [str(d / JJ), "--filter-tau-s", "-0.5"],
    r"clip\.txt: expected a motion file ending in \.bvh, \.npz, \.c3d, \.csv":
        lambda d, t: [str(t / "clip.txt")],
}


@pytest.mark.parametrize(("message", "extra"), BAD_CLI.items(), ids=list(BAD_CLI))
def test_bad_input_is_one_line_exit_2(shared_data: Path, tmp_path: Path, capsys, message: str,
                                      extra) -> None:
    (tmp_path / "clip.txt").write_text("not motion\n")
    out = tmp_path / "out.csv"
    status = main(["synth", "default", *extra(shared_data, tmp_path), "--out", str(out)])
    err = capsys.readouterr().err
    assert status == 2
    assert err.count("\n") == 1 and err.startswith("effortface synth: error: "), err
    assert re.search(message, err), err
    assert not out.exists()


def test_bad_model_dir(shared_data: Path, tmp_path: Path, capsys) -> None:
    status = main(["synth", str(tmp_path / "nomodel"), str(shared_data / JJ), "--out",
                   str(tmp_path / "o.csv")])
    assert status == 2 and "nomodel: expected a model folder" in capsys.readouterr().err


def test_user_mapping_file_maps_unknown_joints(shared_data: Path, tmp_path: Path) -> None:
    """The renamed skeleton that fails above works with a mapping file, giving the same curves."""
    import json

    from effortface.synth.segments import CONVENTIONS

    renamed = {"LeftUpLeg": "Bone_leftupleg_x", "LeftLeg": "Bone_leftleg_x",
               "LeftFoot": "Bone_leftfoot_x"}

    def rename(end):
        if isinstance(end, str):
            return "|".join(renamed.get(j, j) for j in end.split("|"))
        return [rename(e) for e in end]

    mapping = {seg: [rename(p), rename(d)] for seg, (p, d) in CONVENTIONS["CMU"].items()}
    (tmp_path / "map.json").write_text(json.dumps(mapping))
    odd = _unknown_joints_bvh(shared_data, tmp_path)
    assert main(["synth", "default", str(odd), "--out", str(tmp_path / "odd.csv"),
                 "--mapping", str(tmp_path / "map.json")]) == 0
    assert main(["synth", "default", str(shared_data / JJ), "--out", str(tmp_path / "jj.csv")]) == 0
    a, b = _rows(tmp_path / "odd.csv"), _rows(tmp_path / "jj.csv")
    for key in ("w_per_kg", "hr_bpm", "eye_squint"):
        np.testing.assert_allclose([float(r[key]) for r in a], [float(r[key]) for r in b],
                                   rtol=1e-8, err_msg=key)


AMP = "motion/amp_humanoid_walk.npz"


def _npz_with(shared_data: Path, tmp_path: Path, name: str, **changes) -> Path:
    """A copy of the AMP walk clip with arrays replaced (callables edit a copy of the old array)."""
    with np.load(shared_data / AMP, allow_pickle=False) as npz:
        data = {k: npz[k] for k in npz.files}
    for key, value in changes.items():
        data[key] = value(data[key].copy()) if callable(value) else value
    np.savez(tmp_path / name, **data)
    return tmp_path / name


def _first(value):
    def edit(a: np.ndarray) -> np.ndarray:
        a.flat[0] = value
        return a
    return edit


def _map(tmp_path: Path, value) -> str:
    import json

    (tmp_path / "map.json").write_text(json.dumps({"trunk": value}))
    return str(tmp_path / "map.json")


BAD_AUDIT = {
    # item 1: parentsself.npz hung forever, parents99.npz raised IndexError
    r"parentsself\.npz: parent_indices: expected -1 or the index of an earlier joint":
        lambda d, t: [str(_npz_with(d, t, "parentsself.npz", parent_indices=_first(0)))],
    r"parents99\.npz: parent_indices: .*parent 99":
        lambda d, t: [str(_npz_with(d, t, "parents99.npz", parent_indices=_first(99)))],
    # item 2: NaN values gave NaN output rows
    r"nan\.npz: root_translation: expected finite numbers, found nan at frame 0":
        lambda d, t: [str(_npz_with(d, t, "nan.npz", root_translation=_first(np.nan)))],
    r"nanvals\.bvh: line 188: expected finite numbers in frame 0, found nan":
        lambda d, t: [str(_bvh_with(d, t, "nanvals.bvh", "-0.0035 15.8971", "nan 15.8971"))],
    # item 3: tracebacks and misleading messages
    r"empty\.npz: expected a readable \.npz motion file":
        lambda d, t: [str(_touch(t / "empty.npz"))],
    r"fps0\.npz: fps: expected one positive frame rate, found 0":
        lambda d, t: [str(_npz_with(d, t, "fps0.npz", fps=np.array(0.0)))],
    r"map\.json: expected \[proximal, distal\] joint names .*bad entries: trunk":
        lambda d, t: [str(d / AMP), "--mapping", _map(t, [1, 2])],
    r"onejoint\.bvh: expected a skeleton whose rest pose is 1\.1-2\.3 m tall.*--unit-m M":
        lambda d, t: [str(_onejoint(t))],
    r"--out .*: expected a file path, found a folder":
        lambda d, t: [str(d / AMP), "--out", str(t), "--force"],
    r"--out /proc/x\.csv: expected a writable file":
        lambda d, t: [str(d / AMP), "--out", "/proc/x.csv"],
    r"--unit-m: expected a length in metres above 0, found 0$":
        lambda d, t: [str(d / JJ), "--unit-m", "0"],
    r"--unit-m: expected a length in metres above 0, found nan":
        lambda d, t: [str(d / JJ), "--unit-m", "nan"],
    r"--unit-m: expected a length in metres above 0, found inf":
        lambda d, t: [str(d / JJ), "--unit-m", "inf"],
}


def _touch(path: Path) -> Path:
    path.write_bytes(b"")
    return path


def _bvh_with(shared_data: Path, tmp_path: Path, name: str, old: str, new: str) -> Path:
    text = (shared_data / JJ).read_text()
    assert old in text
    (tmp_path / name).write_text(text.replace(old, new, 1))
    return tmp_path / name


def _onejoint(tmp_path: Path) -> Path:
    path = tmp_path / "onejoint.bvh"
    path.write_text("HIERARCHY\nROOT hips\n{\n  OFFSET 0 0 0\n  CHANNELS 3 Xposition Yposition Zposition\n"
                    "  End Site\n  {\n    OFFSET 0 1 0\n  }\n}\nMOTION\nFrames: 2\nFrame Time: 0.01\n"
                    "0 0 0\n0 0 0\n")
    return path


@pytest.mark.parametrize(("message", "extra"), BAD_AUDIT.items(), ids=list(range(len(BAD_AUDIT))))
def test_audit_bad_inputs_are_one_line_exit_2(shared_data: Path, tmp_path: Path, capsys, message: str,
                                              extra) -> None:
    """Inputs from the CLI audit that hung, raised tracebacks, gave NaN rows or misleading text."""
    args = extra(shared_data, tmp_path)
    if "--out" not in args:
        args += ["--out", str(tmp_path / "out.csv")]
    status = main(["synth", "default", *args])
    err = capsys.readouterr().err
    assert status == 2
    assert err.count("\n") == 1 and err.startswith("effortface synth: error: "), err
    assert re.search(message, err), err
    assert not (tmp_path / "out.csv").exists()


@pytest.mark.parametrize("arkit", [None, 3, ["jawOpen"]], ids=["null", "number", "list"])
def test_livelink_bad_arkit_entry_is_one_line(shared_data: Path, tmp_path: Path, capsys, arkit, make_bundle) -> None:
    """An arkit entry that is not a string loaded fine, then crashed --format livelink."""
    import json

    folder = write_bundle(make_bundle(), tmp_path / "model")
    doc = json.loads((folder / "model.json").read_text())
    doc["blendshapes"][1]["arkit"] = [arkit]
    (folder / "model.json").write_text(json.dumps(doc))
    out = tmp_path / "take.csv"
    status = main(["synth", str(folder), str(shared_data / AMP), "--out", str(out), "--format", "livelink"])
    err = capsys.readouterr().err
    assert status == 2 and err.count("\n") == 1, err
    assert re.search(r"model\.json\.blendshapes\[1\]\.arkit: expected ARKit blendshape names", err), err
    assert not out.exists()


def test_synth_filters_the_weights_by_default(shared_data: Path, tmp_path: Path) -> None:
    """synth's weights go through the output filter (0.15 s) unless --filter-tau-s 0 asks for raw ones."""
    smooth, raw = tmp_path / "smooth.csv", tmp_path / "raw.csv"
    assert main(["synth", "default", str(shared_data / JJ), "--out", str(smooth)]) == 0
    assert main(["synth", "default", str(shared_data / JJ), "--out", str(raw), "--filter-tau-s", "0"]) == 0
    names = list(DEFAULT_SET.names)
    weights = [np.genfromtxt(f, delimiter=",", names=True) for f in (smooth, raw)]
    smooth_w, raw_w = (np.column_stack([w[n] for n in names]) for w in weights)
    assert jitter(smooth_w) < jitter(raw_w) / 2


#: what one clip's ``effortface synth`` must not import: scipy (scipy.signal alone costs 0.7 s of
#: start-up: the filters are effortface.synth.iir's), the training, video and GUI libraries, and
#: what only a folder of clips needs (tqdm, dask)
SYNTH_NEVER_IMPORTS = ("scipy", "sklearn", "pandas", "cv2", "PySide6", "pyqtgraph", "matplotlib",
                       "onnx", "onnxruntime", "tqdm", "dask", "distributed")


def test_synth_of_one_clip_imports_nothing_heavy(shared_data: Path, tmp_path: Path) -> None:
    """The whole-process start-up gain of issue 15 (a 10-minute clip in 2 s, not 5): a fresh
    interpreter runs the command and lists the top-level packages it imported."""
    code = ("import json, sys; from effortface.cli import main; status = main(sys.argv[1:]); "
            "print(json.dumps(sorted({m.split('.')[0] for m in sys.modules}))); sys.exit(status)")
    done = subprocess.run([sys.executable, "-c", code, "synth", "default", str(shared_data / JJ),
                           "--out", str(tmp_path / "x.csv")], cwd=ROOT, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    imported = set(json.loads(done.stdout.strip().splitlines()[-1]))
    assert "effortface" in imported and "numpy" in imported
    assert not imported & set(SYNTH_NEVER_IMPORTS), sorted(imported & set(SYNTH_NEVER_IMPORTS))
