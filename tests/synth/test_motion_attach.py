"""``effortface motion attach``: real clips put on a session's clock by an offset or a sync jump."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from effortface.cli import main
from effortface.synth.motion import read_motion, read_positions_csv
from effortface.synth.work import derive_work

SAMPLES = Path(__file__).resolve().parents[2] / "sample_sessions"
SESSION = "P01_20260119-140000_strength"  # 215 s of heart rate and video, no motion/
TRUE_OFFSET_S = 40.123
FULL = "cmu_13_29_full_30fps.bvh"  # starts with jumping jacks: its first flight is the sync jump


def _session(tmp_path: Path, sync_times_s: list[float]) -> Path:
    folder = Path(shutil.copytree(SAMPLES / SESSION, tmp_path / SESSION,
                                  ignore=shutil.ignore_patterns("video.avi", "serial", "work.csv")))
    with open(folder / "events.csv", "a", encoding="utf-8") as fh:
        fh.writelines(f"{t:.4f},sync,jump,\n" for t in sync_times_s)
    return folder


def _raw_apexes_s(clip: Path, windows_s: list[tuple[float, float]]) -> list[float]:
    """Independent apex times: the frame of the highest raw (unfiltered) root in each window."""
    motion = read_motion(clip)
    z, t = motion.positions_m[:, 0, 2], motion.t_s
    return [float(t[(t >= a) & (t < b)][np.argmax(z[(t >= a) & (t < b)])]) for a, b in windows_s]


def _attach(folder: Path, clip: Path, *how: str) -> int:
    return main(["motion", "attach", str(folder), str(clip), *how])


def _clip_seconds(folder: Path) -> tuple[np.ndarray, np.ndarray]:
    work = derive_work(folder)
    mask = np.array([s.startswith("motion:") for s in work.source])
    return work.t_s[mask], work.w_per_kg[mask]


def test_sync_jump_aligns_like_the_true_offset(shared_data: Path, tmp_path: Path,
                                               capsys: pytest.CaptureFixture) -> None:
    clip = shared_data / "motion" / FULL
    (apex_s,) = _raw_apexes_s(clip, [(0.0, 0.6)])
    by_sync = _session(tmp_path / "sync", [5.0, TRUE_OFFSET_S + apex_s])  # an earlier take's jump too
    by_offset = _session(tmp_path / "offset", [])
    assert _attach(by_sync, clip, "--sync") == 2  # one clip jump, two logged: the operator must say which
    assert _one_error_line(capsys).endswith("found 2 fitting equally (at 5.000, 40.456 s); give --sync T with "
                                            "the one to use")
    assert _attach(by_sync, clip, "--sync", "40") == 0
    assert re.fullmatch(r".* offset 40\.\d{3} s from the sync jump \(1 matched, not measurable with one jump\)\n",
                        capsys.readouterr().out)
    assert _attach(by_offset, clip, "--offset", str(TRUE_OFFSET_S)) == 0
    entry = json.loads((by_sync / "motion" / "motion.json").read_text())["files"][0]
    assert entry["path"] == FULL and entry["aligned"] == "sync jump"
    assert abs(entry["offset_s"] - TRUE_OFFSET_S) < 0.1
    t_sync, w_sync = _clip_seconds(by_sync)
    t_true, w_true = _clip_seconds(by_offset)
    np.testing.assert_array_equal(t_sync, t_true)
    assert len(t_sync) >= 37
    assert np.abs(w_sync - w_true).mean() < 0.05 * w_true.mean()
    assert (by_sync / "motion" / FULL).read_bytes() == clip.read_bytes()


def _positions_csv(clip: Path, out: Path) -> Path:
    """The clip as a joint-positions CSV (metres, Z up), with its tree in a comment."""
    m = read_motion(clip)
    header = ["t_s"] + [f"{n}_{a}" for n in m.joint_names for a in "xyz"]
    tree = ", ".join(f"{m.joint_names[j]}={m.joint_names[p]}" for j, p in enumerate(m.parents) if p >= 0)
    rows = np.column_stack([m.t_s, m.positions_m.reshape(m.n_frames, -1)])
    with open(out, "w", encoding="utf-8") as fh:
        fh.write(f"# parents: {tree}\n{','.join(header)}\n")
        np.savetxt(fh, rows, delimiter=",", fmt="%.6f")
    return out


def test_several_jumps_give_a_residual_and_a_positions_csv_works_like_its_source(
        shared_data: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    npz = shared_data / "motion" / "amp_humanoid_hop.npz"
    csv_clip = _positions_csv(npz, tmp_path / "hop.csv")
    again = read_positions_csv(csv_clip)
    np.testing.assert_allclose(again.positions_m, read_motion(npz).positions_m, atol=1e-6)
    apexes = _raw_apexes_s(npz, [(0.5, 1.2), (2.1, 2.8), (3.5, 4.2)])
    folder = _session(tmp_path, [TRUE_OFFSET_S + a for a in apexes])
    assert _attach(folder, csv_clip, "--sync") == 0
    out = capsys.readouterr().out
    residual = float(re.search(r"\(3 matched, residual (\d\.\d{3}) s\)", out)[1])
    assert residual < 0.05
    entry = json.loads((folder / "motion" / "motion.json").read_text())["files"][0]
    assert abs(entry["offset_s"] - TRUE_OFFSET_S) < 0.1 and entry["format"] == "joint positions csv"


def _one_error_line(capsys: pytest.CaptureFixture) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


BAD = {
    "no jump in the clip": ("amp_humanoid_walk.npz", ["--sync"], [3.0],
                            r"{clip}: expected a jump \(the root rising 0.05 m or more in free fall\) in the "
                            r"clip's vertical root motion to align with the sync event, found none; give --offset S"),
    "no sync event": (FULL, ["--sync"], [],
                      r"{session}/events.csv: expected a sync row labelled 'jump' \(t_s,sync,jump,\) to align "
                      r"the clip with, found none"),
    "not a clip": ("../motion_and_physiology_PROVENANCE.md", ["--offset", "1"], [],
                   r"{clip}: expected a clip ending in .bvh, .c3d, .csv, .npz, found '.md'"),
    "not finite": (FULL, ["--offset", "nan"], [], r"--offset: expected a finite number of seconds, found nan"),
}


@pytest.mark.parametrize("case", BAD)
def test_bad_attach_exit_2_with_one_line_and_write_nothing(shared_data: Path, tmp_path: Path,
                                                          capsys: pytest.CaptureFixture, case: str) -> None:
    name, how, sync, message = BAD[case]
    folder = _session(tmp_path, sync)
    clip = (shared_data / "motion" / name).resolve()
    assert _attach(folder, clip, *how) == 2
    expected = "effortface motion: error: " + message.format(clip=re.escape(str(clip)), session=re.escape(str(folder)))
    assert re.match(expected, _one_error_line(capsys))
    assert not (folder / "motion").exists()


def test_a_clip_already_attached_is_not_overwritten(shared_data: Path, tmp_path: Path,
                                                    capsys: pytest.CaptureFixture) -> None:
    folder = _session(tmp_path, [])
    clip = shared_data / "motion" / FULL
    assert _attach(folder, clip, "--offset", "3") == 0
    before = (folder / "motion" / "motion.json").read_bytes()
    assert _attach(folder, clip, "--offset", "9") == 2
    assert _one_error_line(capsys).endswith(f"motion/{FULL}: expected a new clip name in motion/, found one "
                                            "(not overwritten)")
    assert (folder / "motion" / "motion.json").read_bytes() == before


def test_a_clip_carries_the_loads_of_the_exercise_log(shared_data: Path, tmp_path: Path) -> None:
    """Without load keys in motion.json, the log's load rows in force at each second load the body."""
    clip = shared_data / "motion" / "cmu_13_29_squats_120fps.bvh"  # 6.8 s
    offset_s = 20.0  # inside the sample log's first squat set: its loads are logged at 15 and 45 s
    folder = _session(tmp_path, [])
    with open(folder / "events.csv", "a", encoding="utf-8") as fh:
        fh.write(f"{offset_s + 3.5:.4f},load,back_kg,20\n")  # the bar goes on mid-clip
    assert _attach(folder, clip, "--offset", str(offset_s)) == 0
    t, w_log = _clip_seconds(folder)
    loaded = t >= offset_s + 3.5
    index = folder / "motion" / "motion.json"
    entries = json.loads(index.read_text())
    fixed = {}
    for load_kg in (0.0, 20.0):  # the same clip with one explicit load for the whole clip
        entries["files"][0]["load_back_kg"] = load_kg
        index.write_text(json.dumps(entries))
        fixed[load_kg] = _clip_seconds(folder)[1]
    np.testing.assert_allclose(w_log[~loaded], fixed[0.0][~loaded])
    np.testing.assert_allclose(w_log[loaded], fixed[20.0][loaded])
    assert (fixed[20.0][loaded] > fixed[0.0][loaded]).all()
