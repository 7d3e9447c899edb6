"""The one joint-positions CSV reader: both dialects (``<joint>_x_m`` and ``<joint>_x`` columns) share
their errors (file, line, column, expected, found), their time rule and their tree sources."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from effortface.synth.motion import MotionFormatError, read_motion
from effortface.synth.motion_csv import is_positions_csv, read_positions_csv, write_positions_csv
from effortface.synth.synth_session import find_clips

#: the two dialects' axis suffixes
DIALECTS = {"metres": ("_x_m", "_y_m", "_z_m"), "plain": ("_x", "_y", "_z")}


def _header(dialect: str, joints: tuple[str, ...] = ("Hips", "Spine")) -> str:
    return ",".join(["t_s"] + [j + a for j in joints for a in DIALECTS[dialect]])


def _rows(t_s: list[float], n_joints: int = 2) -> str:
    return "".join(",".join([f"{t:g}"] + [f"{0.1 * k + t:g}" for k in range(3 * n_joints)]) + "\n" for t in t_s)


def _write(tmp_path: Path, text: str, name: str = "clip.csv") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


TEN_FRAMES = [k / 100 for k in range(10)]
BAD = {
    "a missing _y column": (lambda d: _header(d).replace(f"Hips{DIALECTS[d][1]},", "") + "\n" + _rows(TEN_FRAMES),
                            r"clip\.csv: line 1, column 2: expected Hips{x},Hips{y},Hips{z}, "
                            r"found 'Hips{x},Hips{z},Spine{x}'"),
    "a joint named twice": (lambda d: _header(d, ("Hips", "Hips")) + "\n" + _rows(TEN_FRAMES),
                            r"clip\.csv: line 1, column 5: expected a joint name not used before, found 'Hips' again"),
    "a cell that is not a number": (lambda d: _header(d) + "\n" + _rows(TEN_FRAMES[:2]) + "0.02,0,oops,0,0,0,0\n"
                                    + _rows(TEN_FRAMES[3:]),
                                    r"clip\.csv: expected rows of 7 numbers \(t_s, then x, y, z per joint\), found "
                                    r"'oops' at line 4, column 3"),
    "a short row": (lambda d: _header(d) + "\n" + _rows(TEN_FRAMES[:4]) + "0.04,0,0\n",
                    r"clip\.csv: expected rows of 7 numbers .*, found 3 values at line 6"),
    "a NaN": (lambda d: _header(d) + "\n" + _rows(TEN_FRAMES[:5]) + "0.05,0,0,0,0,nan,0\n",
              r"clip\.csv: expected rows of 7 numbers .*, found 'nan' at line 7, column 6"),
    "a time going back": (lambda d: "# take 3\n" + _header(d) + "\n\n" + _rows([0, 0.01, 0.02, 0.015, 0.03]),
                          r"clip\.csv: line 7: t_s: expected increasing times, found 0\.015 after 0\.02"),
    "a dropped frame": (lambda d: _header(d) + "\n" + _rows([0, 0.01, 0.02, 0.04, 0.05, 0.06]),
                        r"clip\.csv: line 5: t_s: expected a frame every 0\.01 s \(steps within 50% of it\), found a "
                        r"step of 0\.02 s \(a dropped or repeated frame\?\)"),
    "one frame": (lambda d: _header(d) + "\n" + _rows([0]),
                  r"clip\.csv: expected at least 2 frames \(rows after the header\), found 1"),
    "comments only": (lambda d: "# parents: Spine=Hips\n\n",
                      r"clip\.csv: line 1: expected the header t_s,<joint>_x_m,.* or t_s,<joint>_x,.*, found no line "
                      r"but comments"),
    "a parent after its child": (lambda d: "# parents: Hips=Spine\n" + _header(d) + "\n" + _rows(TEN_FRAMES),
                                 r"clip\.csv: line 1: parents: expected each joint's parent to be a joint of an "
                                 r"earlier column \(parents first\), found Hips=Spine"),
    "a parent not in the header": (lambda d: _header(d) + "\n# parents: Spine=Pelvis\n" + _rows(TEN_FRAMES),
                                   r"clip\.csv: line 2: parents: expected child=parent joint names of the header, "
                                   r"found 'Spine=Pelvis'"),
}


@pytest.mark.parametrize("dialect", DIALECTS)
@pytest.mark.parametrize("case", BAD)
def test_both_dialects_give_the_same_one_line_errors(tmp_path: Path, case: str, dialect: str) -> None:
    make, message = BAD[case]
    x, y, z = DIALECTS[dialect]
    path = _write(tmp_path, make(dialect))
    with pytest.raises(MotionFormatError, match=message.format(x=x, y=y, z=z)) as caught:
        read_motion(path)
    assert len(str(caught.value).splitlines()) == 1


@pytest.mark.parametrize("dialect", DIALECTS)
def test_comments_blank_lines_and_clock_jitter_are_read_in_both_dialects(tmp_path: Path, dialect: str) -> None:
    rng = np.random.default_rng(4)
    t_s = np.arange(240) / 120 + rng.uniform(-0.0015, 0.0015, 240)  # LSL-like stamps: steps 8.3 ms +- 36 %
    text = f"# exported by a test\n\n{_header(dialect)}\n# parents: Spine=Hips\n" + _rows(list(t_s))
    motion = read_motion(_write(tmp_path, text))
    assert motion.joint_names == ("Hips", "Spine") and list(motion.parents) == [-1, 0]
    assert motion.n_frames == 240 and motion.fps == pytest.approx(120, rel=0.02)
    assert is_positions_csv(tmp_path / "clip.csv")


@pytest.mark.parametrize("dialect", DIALECTS)
def test_the_tree_comes_from_a_comment_or_a_skeleton_file_not_both(tmp_path: Path, dialect: str) -> None:
    (tmp_path / "clip.skeleton.json").write_text('{"joints": ["Hips", "Spine"], "parents": [-1, 0]}')
    path = _write(tmp_path, _header(dialect) + "\n" + _rows(TEN_FRAMES))
    assert list(read_positions_csv(path).parents) == [-1, 0]
    _write(tmp_path, "# parents: Spine=Hips\n" + path.read_text())
    with pytest.raises(MotionFormatError, match=r"clip\.csv: line 1: expected the tree in one place, found a "
                                                r"'# parents:' comment and clip\.skeleton\.json beside the clip"):
        read_positions_csv(path)
    (tmp_path / "clip.skeleton.json").write_text('{"joints": ["Pelvis", "Spine"], "parents": [-1, 0]}')
    _write(tmp_path, _header(dialect) + "\n" + _rows(TEN_FRAMES))
    with pytest.raises(MotionFormatError, match=r"clip\.skeleton\.json: joints: expected the 2 joints of clip\.csv "
                                                r"in its column order \(Hips, Spine\), found 2 \(Pelvis, Spine\)"):
        read_positions_csv(path)


def test_default_trees_are_kept_per_dialect(tmp_path: Path) -> None:
    """As documented before the readers were one: ``_x_m`` files without a skeleton file are all
    roots; ``_x`` files without a comment hang every joint from the first."""
    metres = read_positions_csv(_write(tmp_path, _header("metres") + "\n" + _rows(TEN_FRAMES), "a.csv"))
    plain = read_positions_csv(_write(tmp_path, _header("plain") + "\n" + _rows(TEN_FRAMES), "b.csv"))
    assert list(metres.parents) == [-1, -1] and list(plain.parents) == [-1, 0]
    np.testing.assert_array_equal(metres.positions_m, plain.positions_m)
    assert metres.fps == plain.fps == pytest.approx(100)


def test_the_clip_list_offers_both_dialects(shared_data: Path, tmp_path: Path) -> None:
    bvh = read_motion(shared_data / "motion/cmu_13_29_squats_120fps.bvh").slice_s(0, 0.2)
    write_positions_csv(tmp_path / "a_metres.csv", bvh)
    _write(tmp_path, "# parents: Spine=Hips\n" + _header("plain") + "\n" + _rows(TEN_FRAMES), "b_plain.csv")
    _write(tmp_path, "t_s,hr_bpm,rr_ms\n0,60,1000\n", "heart_rate.csv")
    assert [p.name for p in find_clips(tmp_path)] == ["a_metres.csv", "b_plain.csv"]


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="FIFOs are POSIX")
@pytest.mark.parametrize("suffix", [".csv", ".c3d"])
def test_a_fifo_is_refused_not_read_forever(tmp_path: Path, suffix: str) -> None:
    fifo = tmp_path / f"clip{suffix}"
    os.mkfifo(fifo)
    code = ("from effortface.synth.motion import read_motion, MotionFormatError\n"
            f"try:\n    read_motion({str(fifo)!r})\nexcept MotionFormatError as exc:\n    print(exc)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.stdout.strip() == f"{fifo}: expected a motion file ({suffix}), found a special file (FIFO, device or socket)", out.stderr
