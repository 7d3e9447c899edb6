"""Issue 37: ``motion attach`` of a joint-positions CSV in the ``_x_m`` dialect (what
``write_positions_csv`` writes, with its tree in ``<stem>.skeleton.json`` beside it) copies the
skeleton file with the clip. Before, only the CSV was copied, so ``work``, ``train`` and ``export bids``
read it with every joint a root and failed with a StopIteration traceback."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

from effortface.cli import main
from effortface.synth.motion import read_motion
from effortface.synth.motion_csv import write_positions_csv
from effortface.synth.work import derive_work, read_work_csv
from effortface.train.dataset import session_table

SAMPLES = Path(__file__).resolve().parents[2] / "sample_sessions"
SESSION = "P01_20260119-140000_strength"
SQUATS = SAMPLES / "P02_20260112-113700_strength" / "motion" / "squats_set2.bvh"   # CMU mocap, in the repo
OFFSET_S = 30.0


def _session(tmp_path: Path) -> Path:
    return Path(shutil.copytree(SAMPLES / SESSION, tmp_path / "lab" / SESSION,
                                ignore=shutil.ignore_patterns("video.avi", "serial")))


def _clip(tmp_path: Path) -> Path:
    """Ten seconds of the squats as the product writes a positions CSV (and its skeleton file)."""
    (tmp_path / "clips").mkdir()
    return write_positions_csv(tmp_path / "clips" / "squats.csv", read_motion(SQUATS).slice_s(0, 10))


def test_the_skeleton_travels_with_the_clip(tmp_path, capsys):
    folder, clip = _session(tmp_path), _clip(tmp_path)
    skeleton = clip.with_name("squats.skeleton.json")
    assert main(["motion", "attach", str(folder), str(clip), "--offset", str(OFFSET_S)]) == 0
    assert sorted(p.name for p in (folder / "motion").iterdir()) == ["motion.json", "squats.csv",
                                                                     "squats.skeleton.json"]
    assert (folder / "motion" / "squats.skeleton.json").read_bytes() == skeleton.read_bytes()
    attached = read_motion(folder / "motion" / "squats.csv")
    assert attached.parents.tolist() == read_motion(clip).parents.tolist() and (attached.parents < 0).sum() == 1
    # work (as `effortface work` writes it), train's table and the BIDS export all read it
    capsys.readouterr()
    assert main(["work", str(folder)]) == 0
    table = read_work_csv(folder / "work.csv")
    motion_s = [t for t, src in zip(table.t_s, table.source) if src == "motion:squats.csv"]
    assert motion_s[0] == OFFSET_S and len(motion_s) == 10
    np.testing.assert_allclose(table.w_per_kg, derive_work(folder).w_per_kg, atol=5e-5, equal_nan=True)
    assert len(session_table(folder)) > 0
    out = tmp_path / "ds"
    done = subprocess.run([sys.executable, "-m", "effortface", "export", "bids", folder.parent, "--out", out],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0 and done.stderr == "", done.stderr
    (motion,) = out.rglob("*_tracksys-mocap_motion.tsv")
    assert json.loads(motion.with_suffix(".json").read_text())["TrackedPointsCount"] == len(attached.joint_names)
    from tests.interop.test_bids import _validate

    assert [i for i in _validate(out) if i["severity"] == "error"] == []


def test_a_skeleton_of_that_name_in_motion_is_never_overwritten(tmp_path, capsys):
    folder, clip = _session(tmp_path), _clip(tmp_path)
    (folder / "motion").mkdir()
    (folder / "motion" / "squats.skeleton.json").write_text('{"joints": [], "parents": []}')
    assert main(["motion", "attach", str(folder), str(clip), "--offset", str(OFFSET_S)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"effortface motion: error: {folder / 'motion' / 'squats.skeleton.json'}: expected a new "
                   f"skeleton file name in motion/ for squats.csv, found one (not overwritten)"]
    assert sorted(p.name for p in (folder / "motion").iterdir()) == ["squats.skeleton.json"]
    assert (folder / "motion" / "squats.skeleton.json").read_text() == '{"joints": [], "parents": []}'


def test_a_positions_csv_without_its_tree_is_one_line_not_a_traceback(tmp_path, capsys):
    """A `_x_m` clip whose skeleton file was lost (every joint a root): before, `work` ended in
    ``StopIteration`` (RuntimeError in a generator) from the segment frames."""
    folder, clip = _session(tmp_path), _clip(tmp_path)
    assert main(["motion", "attach", str(folder), str(clip), "--offset", str(OFFSET_S)]) == 0
    (folder / "motion" / "squats.skeleton.json").unlink()
    capsys.readouterr()
    assert main(["work", str(folder)]) == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert line.startswith(f"effortface work: error: {folder / 'motion' / 'squats.csv'}: ")
    assert line.endswith("in one skeleton tree, found them in separate trees: a joint-positions CSV needs its "
                         "skeleton file squats.skeleton.json beside it (or a '# parents:' comment)")
    assert not (folder / "work.csv").exists()


def test_a_csv_with_its_tree_in_a_comment_needs_no_skeleton_file(tmp_path):
    folder, clip = _session(tmp_path), _clip(tmp_path)
    m = read_motion(clip)
    tree = ", ".join(f"{m.joint_names[j]}={m.joint_names[p]}" for j, p in enumerate(m.parents) if p >= 0)
    clip.with_name("squats.skeleton.json").unlink()
    clip.write_text(f"# parents: {tree}\n" + clip.read_text())
    assert main(["motion", "attach", str(folder), str(clip), "--offset", str(OFFSET_S)]) == 0
    assert sorted(p.name for p in (folder / "motion").iterdir()) == ["motion.json", "squats.csv"]
    assert np.isfinite(derive_work(folder).w_per_kg).sum() > 0
