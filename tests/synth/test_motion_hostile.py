"""Issue 29: every motion reader answers a hostile file in one line naming the file, frame and field,
in single-clip ``synth`` as in folder mode; no NaN weight is ever written."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from effortface.cli import main
from effortface.synth.motion import MAX_BVH_DEPTH, MotionFormatError, read_motion

SQUATS = "motion/cmu_13_29_squats_120fps.bvh"


def _bvh_lines(shared_data: Path) -> list[str]:
    return (shared_data / SQUATS).read_text().splitlines()


def _motion_at(lines: list[str]) -> int:
    return next(i for i, line in enumerate(lines) if line.strip().upper() == "MOTION")


def _write(path: Path, lines: list[str]) -> Path:
    path.write_text("\n".join(lines) + "\n")
    return path


def _huge_bvh(shared_data: Path, tmp_path: Path) -> Path:
    lines = _bvh_lines(shared_data)
    first = _motion_at(lines) + 3
    fields = lines[first + 5].split()
    fields[0] = "1e308"  # the root's Xposition in frame 5
    lines[first + 5] = " ".join(fields)
    return _write(tmp_path / "huge.bvh", lines)


def test_a_frame_of_huge_finite_values_is_refused_naming_frame_and_field(shared_data, tmp_path) -> None:
    path = _huge_bvh(shared_data, tmp_path)
    with pytest.raises(MotionFormatError, match=r"huge\.bvh: positions_m: expected a number from -1000 to 1000 m, "
                                                r"found .* at frame 5, joint "):
        read_motion(path)


def test_a_huge_value_in_a_positions_csv_is_refused(tmp_path) -> None:
    rows = ["t_s,hip_x_m,hip_y_m,hip_z_m"] + [f"{k / 100:.2f},0,0,1" for k in range(20)]
    rows[8] = "0.07,1e200,0,1"
    path = tmp_path / "clip.csv"
    path.write_text("\n".join(rows) + "\n")
    with pytest.raises(MotionFormatError, match=r"clip\.csv: positions_m: .* found 1e\+200 at frame 7, joint 'hip'"):
        read_motion(path)


def test_a_huge_root_translation_in_an_npz_is_refused(shared_data, tmp_path) -> None:
    with np.load(shared_data / "motion/amp_humanoid_walk.npz") as data:
        arrays = {k: data[k] for k in data.files}
    arrays["root_translation"] = arrays["root_translation"].copy()
    arrays["root_translation"][3, 0] = 1e30  # finite in float32
    np.savez(tmp_path / "walk.npz", **arrays)
    with pytest.raises(MotionFormatError, match=r"walk\.npz: positions_m: .* at frame 3, joint "):
        read_motion(tmp_path / "walk.npz")


def _deep_bvh(tmp_path: Path, depth: int) -> Path:
    head = ["HIERARCHY", "ROOT r", "{", "OFFSET 0 0 0", "CHANNELS 3 Xposition Yposition Zposition"]
    head += [f"JOINT j{k} {{ OFFSET 0 1 0 CHANNELS 0" for k in range(depth)]
    head += ["}" * (depth + 1), "MOTION", "Frames: 1", "Frame Time: 0.01", "0 0 0"]
    return _write(tmp_path / "deep.bvh", head)


def _header_bvh(shared_data: Path, tmp_path: Path, frames: str | None = None, frame_time: str | None = None) -> Path:
    lines = _bvh_lines(shared_data)
    at = _motion_at(lines)
    if frames is not None:
        lines[at + 1] = f"Frames: {frames}"
    if frame_time is not None:
        lines[at + 2] = f"Frame Time: {frame_time}"
    return _write(tmp_path / "header.bvh", lines)


def _first_byte_200_c3d(shared_data: Path, tmp_path: Path) -> Path:
    pytest.importorskip("c3d")
    from effortface.synth.c3d_motion import write_c3d_markers

    bvh = read_motion(shared_data / SQUATS).slice_s(0, 0.5)
    markers = {name: bvh.positions_m[:, j] for j, name in enumerate(bvh.joint_names[:6])}
    path = write_c3d_markers(tmp_path / "clip.c3d", markers, bvh.fps)
    blob = bytearray(path.read_bytes())
    blob[0] = 200
    path.write_bytes(bytes(blob))
    return path


CASES = {
    "100k nested joints": (lambda d, t: _deep_bvh(t, 100_000), f"expected joints nested at most {MAX_BVH_DEPTH} deep"),
    "Frames: 1e9 on a short file": (lambda d, t: _header_bvh(d, t, frames="1000000000"),
                                    "Frames: expected at most"),
    "Frame Time 1e-300": (lambda d, t: _header_bvh(d, t, frame_time="1e-300"),
                          "Frame Time: expected a number from 0.0001 to 10 s, found 1e-300"),
    "Frame Time 1e300": (lambda d, t: _header_bvh(d, t, frame_time="1e300"),
                         "Frame Time: expected a number from 0.0001 to 10 s, found 1e+300"),
    "1e308 in a frame": (lambda d, t: _huge_bvh(d, t), "positions_m: expected a number from -1000 to 1000 m"),
    "C3D first byte 200": (_first_byte_200_c3d, "expected a C3D file, found"),
}


@pytest.mark.parametrize("case", list(CASES))
def test_single_clip_synth_answers_in_one_line(shared_data, tmp_path, capsys, case) -> None:
    make, message = CASES[case]
    path = make(shared_data, tmp_path)
    out = tmp_path / "out.csv"
    assert main(["synth", "default", str(path), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(path) in err[0] and message in err[0], err
    assert not out.exists()


def test_folder_synth_counts_the_huge_clip_as_failed(shared_data, tmp_path) -> None:
    clips = tmp_path / "clips"
    clips.mkdir()
    shutil.copy(shared_data / SQUATS, clips / "good.bvh")
    shutil.copy(_huge_bvh(shared_data, tmp_path), clips / "huge.bvh")
    done = subprocess.run([sys.executable, "-m", "effortface", "synth", "default", str(clips), "--out",
                           str(tmp_path / "curves")], capture_output=True, text=True, timeout=300)
    assert done.returncode == 1 and "Traceback" not in done.stderr
    assert "1 of 2 clips failed (skipped)" in done.stderr and "huge.bvh: positions_m" in done.stderr


def test_work_refuses_a_session_clip_with_huge_values(tmp_path, capsys) -> None:
    root = Path(__file__).resolve().parents[2]
    session = Path(shutil.copytree(root / "sample_sessions" / "P02_20260112-113700_strength",
                                   tmp_path / "P02_20260112-113700_strength",
                                   ignore=shutil.ignore_patterns("video.avi", "serial")))
    clip = session / "motion" / "squats_set2.bvh"
    lines = clip.read_text().splitlines()
    first = _motion_at(lines) + 3
    fields = lines[first + 2].split()
    fields[1] = "1e308"
    lines[first + 2] = " ".join(fields)
    _write(clip, lines)
    assert main(["work", str(session)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "squats_set2.bvh: positions_m" in err[0] and "at frame 2" in err[0], err
    assert not (session / "work.csv").exists()
