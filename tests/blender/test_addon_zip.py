"""``effortface blender-addon`` and the add-on's Blender-free part (no bpy needed)."""

from __future__ import annotations

import json
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from effortface import __version__
from effortface.blender import bake
from effortface.blender.package import ADDON_FILES, RUNTIME_DATA, RUNTIME_MODULES
from effortface.cli import main
from effortface.core.blendshapes import DEFAULT_SET
from effortface.core.errors import UserError
from tests.conftest import ROOT


def test_the_bundled_modules_are_exactly_what_the_runtime_imports() -> None:
    code = ("import sys, json, effortface.runtime, effortface.synth.curves_io; "
            "print(json.dumps(sorted(m for m in sys.modules if m == 'effortface' or m.startswith('effortface.')))); "
            "print(json.dumps(sorted(m for m in ('scipy', 'pandas', 'PySide6', 'sklearn', 'cv2') if m in sys.modules)))")
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True,
                          env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})
    loaded, heavy = (json.loads(line) for line in done.stdout.splitlines())
    assert loaded == sorted(RUNTIME_MODULES)
    assert heavy == []  # Blender's Python has numpy but no scipy: the runtime needs none


def test_blender_addon_builds_an_extension_zip(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "addon.zip"
    assert main(["blender-addon", "--out", str(out)]) == 0
    line = capsys.readouterr().out
    assert line.count("\n") == 1 and str(out) in line
    with zipfile.ZipFile(out) as z:
        names = set(z.namelist())
        manifest = z.read("blender_manifest.toml").decode()
    assert set(ADDON_FILES) <= names and "LICENSE" in names
    assert f'version = "{__version__}"' in manifest and 'blender_version_min = "4.2.0"' in manifest
    assert {f"vendor/effortface/{d}" for d in RUNTIME_DATA} <= names
    vendored = {n for n in names if n.startswith("vendor/") and n.endswith(".py")}
    assert len(vendored) == len(RUNTIME_MODULES)
    assert not any("gui" in n or "commands" in n or "train/" in n for n in names)


@pytest.mark.parametrize("case", ["exists", "folder", "suffix", "no_parent"])
def test_blender_addon_refuses_bad_out_in_one_line(case: str, tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    out = {"exists": tmp_path / "a.zip", "folder": tmp_path, "suffix": tmp_path / "a.tar",
           "no_parent": tmp_path / "missing" / "a.zip"}[case]
    if case == "exists":
        out.write_bytes(b"keep")
    assert main(["blender-addon", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("effortface blender-addon: error: --out ") and "Traceback" not in err
    assert str(out) in err
    if case == "exists":
        assert out.read_bytes() == b"keep"
        assert main(["blender-addon", "--out", str(out), "--force"]) == 0
        assert zipfile.is_zipfile(out)
    else:
        assert not (tmp_path / "a.tar").exists() and not (tmp_path / "missing").exists()


def test_skeleton_from_bones_adds_an_end_joint_per_leaf_bone() -> None:
    sk = bake.skeleton_from_bones(["Hips", "Spine", "Head", "LeftUpLeg"], [None, "Hips", "Spine", "Hips"])
    assert sk.joint_names == ("Hips", "Spine", "Head", "LeftUpLeg", "Head_end", "LeftUpLeg_end")
    assert sk.parents == (-1, 0, 1, 0, 2, 3)


def test_joint_positions_and_rotations_follow_the_posed_matrices() -> None:
    sk = bake.skeleton_from_bones(["root", "leaf"], [None, "root"])
    turn = np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]])  # 90 degrees about Z
    mats = np.tile(np.eye(4), (1, 2, 1, 1))
    mats[0, 1, :3, :3] = turn
    mats[0, 1, :3, 3] = (0, 0, 1)
    world = np.eye(4)[None].copy()
    world[0, :3, 3] = (10, 0, 0)
    mats_t = np.swapaxes(mats, -1, -2)  # as foreach_get gives them
    pos = bake.joint_positions(sk, mats_t, np.array([1.0, 2.0]), world)
    assert np.allclose(pos[0], [[10, 0, 0], [10, 0, 1], [8, 0, 1]])  # leaf's Y axis turned to -X
    rot = bake.joint_rotations(sk, mats_t, world)
    assert np.allclose(rot[0, 1], turn) and np.allclose(rot[0, 2], turn)


def test_the_mapping_table_reuses_the_projects_arkit_names() -> None:
    rows = bake.default_rows(DEFAULT_SET)
    assert ("mouth_open", "jawOpen") in rows and ("brow_lower", "browDownRight") in rows
    assert ("eye_squint", "eye_squint") in rows
    found = bake.key_targets(rows, ["Basis", "jawOpen", "eye_squint", "smile"], DEFAULT_SET.names)
    assert found == {"jawOpen": "mouth_open", "eye_squint": "eye_squint"}
    assert bake.key_targets(rows, ["jawOpen"], ["jawOpen", "t_s"]) == {"jawOpen": "jawOpen"}  # Live Link column


def test_frame_range_keeps_the_actions_frames_and_refuses_one_frame() -> None:
    assert bake.frame_range((1, 814), (1.0, 813.0)) == (1, 813)
    with pytest.raises(UserError, match="expected at least two frames"):
        bake.frame_range((20, 30), (1.0, 10.0))


def test_unit_is_detected_as_effortface_synth_detects_bvh() -> None:
    assert bake.unit_m(30.4) == pytest.approx(0.05644)  # a CMU skeleton imported at scale 1
    assert bake.unit_m(1.75) == 1.0 and bake.unit_m(175.0) == pytest.approx(0.01)
    assert bake.unit_m(500.0, 0.004) == 0.004
    with pytest.raises(UserError):
        bake.unit_m(0.001)


def test_a_missing_mapping_file_is_one_line(tmp_path: Path) -> None:
    assert bake.check_mapping_path("  ") is None
    with pytest.raises(UserError, match="expected a JSON mapping file, found no such file"):
        bake.check_mapping_path(str(tmp_path / "none.json"))


def test_the_guide_lists_every_panel_field() -> None:
    """The panel cannot be rendered headless: the guide's table stands for it (docs/guide/blender.md)."""
    import ast

    tree = ast.parse((ROOT / "effortface" / "blender" / "ui.py").read_text())
    settings = next(n for n in ast.walk(tree) if isinstance(n, ast.ClassDef) and n.name == "EFFORTFACE_PG_settings")
    fields = [n.target.id for n in settings.body if isinstance(n, ast.AnnAssign) and isinstance(n.target, ast.Name)]
    guide = (ROOT / "docs" / "guide" / "blender.md").read_text()
    assert len(fields) == 10 and all(f"| `{f}` |" in guide for f in fields), fields
