"""The add-on in a real Blender (``bpy`` 4.5 LTS, headless): installed from the zip that
``effortface blender-addon`` builds, baked on BVH clips imported with Blender's own importer, and
compared frame by frame with ``effortface synth default`` on the same file.

Blender runs in a fresh interpreter of its own (tests/blender/run_in_blender.py under the
``bpy_python`` fixture: a virtual environment with pyproject.toml's ``blender`` extra and Blender's
numpy 1.26, never the project's environment, checked), so the bake uses the runtime the zip bundles,
not this checkout's (checked). ``effortface synth`` runs here, in the project's environment. The clips
are cut to a few seconds to keep the tests short; the 10-minute case is benchmarks/bench_blender.py.
"""

from __future__ import annotations

import json
import re
import subprocess
from pathlib import Path

import numpy as np
import pytest

from effortface.cli import main as cli_main
from effortface.core.blendshapes import DEFAULT_SET
from effortface.synth.curves_io import read_curves
from tests.blender.bpy_env import BpyPython, clean_env
from tests.conftest import ROOT

DRIVER = Path(__file__).with_name("run_in_blender.py")
MOTION = ROOT / "tests" / "data" / "motion"
#: the Must-show bound on |Blender's shape-key value - effortface synth's weight|
MAX_DIFFERENCE = 0.03
#: ARKit shape key -> blendshape (the project's own table, effortface.core.blendshapes)
ARKIT = {arkit: shape.name for shape in DEFAULT_SET.shapes for arkit in shape.arkit}


def trim_bvh(src: Path, dst: Path, n_frames: int) -> Path:
    """The first ``n_frames`` frames of a BVH file (the header's Frames: line changed to match)."""
    return trim_bvh_text(src.read_text(), dst, n_frames)


def trim_bvh_text(text: str, dst: Path, n_frames: int) -> Path:
    """:func:`trim_bvh` on a BVH file's text."""
    lines = text.splitlines()
    at = next(i for i, line in enumerate(lines) if line.strip().startswith("Frame Time"))
    lines[at - 1] = f"Frames: {n_frames}"
    dst.write_text("\n".join(lines[:at + 1 + n_frames]) + "\n")
    return dst


@pytest.fixture(scope="module")
def addon_zip(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("addon") / "effortface_blender.zip"
    assert cli_main(["blender-addon", "--out", str(out)]) == 0
    return out


def in_blender(blender: BpyPython, mode: str, spec: dict, tmp: Path) -> dict:
    """Run the driver in ``blender``'s interpreter (no PYTHONPATH, no user site: nothing of the
    project's environment) with its own Blender user folder; its JSON result."""
    (tmp / "spec.json").write_text(json.dumps(spec))
    env = clean_env()
    env["BLENDER_USER_RESOURCES"] = str(tmp / "blender_user")
    proc = subprocess.run([str(blender.python), str(DRIVER), mode, str(tmp / "spec.json"), str(tmp / "out.json")],
                          cwd=tmp, env=env, capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0 and (tmp / "out.json").is_file(), proc.stderr[-3000:]
    out = json.loads((tmp / "out.json").read_text())
    # Blender's own interpreter, not the project's: bpy and numpy from under its prefix
    for module in ("bpy", "numpy"):
        assert Path(out["modules"][module]).resolve().is_relative_to(blender.prefix.resolve()), out["modules"]
    return out


def bake_and_compare(blender: BpyPython, clip: Path, addon_zip: Path, tmp: Path,
                     **placed: float) -> tuple[float, dict]:
    """Bake ``clip`` in Blender and synthesize it with the command line; (max |difference|, result).
    ``placed``: ``turn_rad`` / ``shift_m`` of the armature object (world space)."""
    out = in_blender(blender, "bake", {"zip": str(addon_zip), "bvh": str(clip), **placed}, tmp)
    assert out["effortface_file"].startswith(str(tmp / "blender_user")), out["effortface_file"]
    assert out["operators"] == [True, True]
    assert cli_main(["synth", "default", str(clip), "--out", str(tmp / "synth.csv")]) == 0
    synth = read_curves(tmp / "synth.csv")
    n = out["last"] - out["first"] + 1
    assert n == len(synth["t_s"]), (n, len(synth["t_s"]), out["scene_range"])
    diffs = {key: float(np.max(np.abs(np.asarray(v) - synth[ARKIT[key]]))) for key, v in out["values"].items()}
    assert set(diffs) == set(ARKIT)
    # heart rate is updated once per simulated second: where Blender's frame rate (fps / fps_base)
    # and the file's differ in the last digits, an update may land one frame apart
    hr_diff = np.abs(np.asarray(out["props"]["effortface_hr_bpm"]) - synth["hr_bpm"])
    print(f"{clip.name}: max |heart rate difference| {hr_diff.max():.3f} bpm, "
          f"{np.mean(hr_diff > 0.5):.2%} of frames above 0.5 bpm")
    assert np.mean(hr_diff > 0.5) < 0.01
    print(f"{clip.name}: {n} frames at {out['fps']:.3f} fps, bake {out['bake_s']:.2f} s, "
          f"max |diff| per key {json.dumps({k: round(d, 5) for k, d in diffs.items()})}")
    return max(diffs.values()), out


def test_cmu_squats_baked_in_blender_match_effortface_synth(bpy_python: BpyPython, addon_zip: Path,
                                                            tmp_path: Path) -> None:
    clip = trim_bvh(MOTION / "cmu_13_29_squats_120fps.bvh", tmp_path / "cmu_squats_3s.bvh", 360)
    worst, out = bake_and_compare(bpy_python, clip, addon_zip, tmp_path)
    assert out["first"] == 1 and out["scene_range"] == [1, 361]  # the importer's scene ends one frame late
    assert abs(out["fps"] - 120.0) < 0.01
    assert max(max(v) for v in out["values"].values()) > 0.01  # a face that moved: a real comparison
    assert worst <= MAX_DIFFERENCE


def test_cmu_jumping_jacks_baked_in_blender_match_effortface_synth(bpy_python: BpyPython, addon_zip: Path,
                                                                   tmp_path: Path) -> None:
    clip = MOTION / "cmu_13_29_jumping_jacks_120fps.bvh"  # 439 frames, 3.7 s
    worst, out = bake_and_compare(bpy_python, clip, addon_zip, tmp_path)
    assert max(max(v) for v in out["values"].values()) > 0.1
    assert worst <= MAX_DIFFERENCE


def test_pymo_walk_baked_in_blender_match_effortface_synth(bpy_python: BpyPython, addon_zip: Path,
                                                           tmp_path: Path) -> None:
    clip = trim_bvh(ROOT / "tests" / "data" / "bvh" / "pymo_walk.bvh", tmp_path / "pymo_walk_3s.bvh", 360)
    worst, _ = bake_and_compare(bpy_python, clip, addon_zip, tmp_path)
    assert worst <= MAX_DIFFERENCE


def test_a_turned_and_moved_armature_object_bakes_the_same_face(bpy_python: BpyPython, addon_zip: Path,
                                                                tmp_path: Path) -> None:
    """Positions are taken in world space: turning the armature object about the vertical and
    moving it (a static placement) changes no energy, so the face is still the file's (laying it
    down does change the world positions: the wrong-selection test's ``lying_down`` case)."""
    clip = trim_bvh(MOTION / "cmu_13_29_squats_120fps.bvh", tmp_path / "cmu_squats_2s.bvh", 240)
    worst, _ = bake_and_compare(bpy_python, clip, addon_zip, tmp_path, turn_rad=2.0, shift_m=5.0)
    assert worst <= MAX_DIFFERENCE


def test_mixamo_named_skeleton_baked_in_blender_match_effortface_synth(bpy_python: BpyPython, addon_zip: Path,
                                                                       tmp_path: Path) -> None:
    """Mixamo's own BVH files may not be redistributed (measured in docs/guide/blender.md: max
    |difference| 0.0002 on two of them); this fixture gives real CMU motion Mixamo's namespaced
    joint names (``mixamorig:Hips``...), which Blender's bones keep and the conventions strip."""
    text = (MOTION / "cmu_13_29_jumping_jacks_120fps.bvh").read_text()
    renamed = re.sub(r"(?m)^(\s*(?:ROOT|JOINT)\s+)(\S+)", r"\1mixamorig:\2", text)
    clip = trim_bvh_text(renamed, tmp_path / "mixamorig_jumping_jacks.bvh", 240)
    worst, out = bake_and_compare(bpy_python, clip, addon_zip, tmp_path)
    assert worst <= MAX_DIFFERENCE


def test_wrong_selections_give_one_line_and_key_nothing(bpy_python: BpyPython, addon_zip: Path,
                                                        tmp_path: Path) -> None:
    clip = trim_bvh(MOTION / "cmu_13_29_squats_120fps.bvh", tmp_path / "short.bvh", 60)
    out = in_blender(bpy_python, "errors", {"zip": str(addon_zip), "bvh": str(clip)}, tmp_path)
    expected = {"no_armature": "expected an active armature, found Face (mesh)",
                "nothing_active": "expected an active armature, found no active object",
                "no_action": "expected an armature with an action, found Still without one",
                "missing_model": "no_such_bundle",
                "lying_down": "unit_m: cannot tell the BVH length unit from a rest-pose height of 4.5",
                "no_shape_keys": "expected selected meshes with shape keys named mouthStretchLeft",
                "unmapped_skeleton": "skeleton joints: expected every segment mapped",
                "missing_mapping": "expected a JSON mapping file, found no such file"}
    for case, (message, keyed) in ((k, out[k]) for k in expected):
        assert message.startswith("Error: Bake effort face: "), (case, message)
        assert "\n" not in message and "Traceback" not in message, (case, message)
        assert keyed == 0, (case, message)
    for case, text in expected.items():
        assert text.lower() in out[case][0].lower(), (case, out[case][0])


def test_import_curves_keys_synth_csv_and_livelink(bpy_python: BpyPython, addon_zip: Path,
                                                   tmp_path: Path) -> None:
    clip = MOTION / "cmu_13_29_jumping_jacks_120fps.bvh"
    csv, live = tmp_path / "face.csv", tmp_path / "face_livelink.csv"
    assert cli_main(["synth", "default", str(clip), "--out", str(csv)]) == 0
    assert cli_main(["synth", "default", str(clip), "--out", str(live), "--format", "livelink"]) == 0
    bad = tmp_path / "bad.csv"
    bad.write_text("time,value\n0,1\n")
    spec = {"zip": str(addon_zip), "fps": 120, "files": [str(csv), str(live), str(bad)]}
    out = in_blender(bpy_python, "import", spec, tmp_path)
    per_frame, livelink = read_curves(csv), read_curves(live)
    got = out[str(csv)]["keyed"]
    assert set(got) == set(ARKIT)
    for key, points in got.items():
        co = np.asarray(points)
        assert np.allclose(co[:, 0], 1 + per_frame["t_s"] * 120, atol=1e-3)
        assert np.allclose(co[:, 1], per_frame[ARKIT[key]], atol=1e-6)
    got = out[str(live)]["keyed"]
    assert set(got) == set(ARKIT)
    for key, points in got.items():
        co = np.asarray(points)
        assert np.allclose(co[:, 0], 1 + livelink["t_s"] * 120, atol=1e-3)
        assert np.allclose(co[:, 1], livelink[key], atol=1e-6)
    assert out[str(bad)]["keyed"] == {}
    assert out[str(bad)]["result"].startswith("Error: Import curves: ")
    assert "expected a header starting with t_s" in out[str(bad)]["result"]


def test_demo_scene_example_runs_and_bakes(bpy_python: BpyPython, tmp_path: Path) -> None:
    """The example in Blender's interpreter, the add-on registered from this checkout's package
    (PYTHONPATH): effortface.blender and the runtime it loads need numpy only, Blender's 1.26 here."""
    env = dict(clean_env(), BLENDER_USER_RESOURCES=str(tmp_path / "blender_user"), PYTHONPATH=str(ROOT))
    proc = subprocess.run([str(bpy_python.python), str(ROOT / "examples" / "blender_demo_scene.py"),
                           "--seconds", "2"], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "add-on: registered from the effortface package" in proc.stdout
    assert "bake: {'FINISHED'}" in proc.stdout
