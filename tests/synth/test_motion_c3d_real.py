"""C3D files as labs have them (issue 24, Must show): real files from other systems
(tests/data/c3d/README.md) through ``effortface synth default FILE``: finite curves for the full-body
ones, one line and exit 2 for the others; per-point and NUL-padded units; short occlusions filled
(stated in the output's provenance), long ones refused naming the point; a head from three markers;
the Qualisys sports set built in; the ezc3d reader with the ``c3d`` package as fallback."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from effortface.synth.c3d_motion import (HEAD_MARKERS, MAX_GAP_S, QUALISYS_SPORTS, fill_gaps, head_centre,
                                                 read_c3d, read_c3d_points, units_per_point)
from effortface.synth.motion import MotionFormatError

DATA = Path(__file__).resolve().parents[1] / "data" / "c3d"
FULL = DATA / "PiG_Calibration-FlatFoot-Full.c3d"
ezc3d = pytest.importorskip("ezc3d")


def _synth(clip: Path, out: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "effortface", "synth", "default", str(clip), "--out", str(out)],
                          capture_output=True, text=True, timeout=600)


def _without_lfhd(tmp: Path) -> Path:
    """The real full-body file with its LFHD marker blanked (ezc3d writes it)."""
    c = ezc3d.c3d(str(FULL))
    labels = list(c["parameters"]["POINT"]["LABELS"]["value"])
    points = c["data"]["points"]
    points[:3, labels.index("LFHD"), :] = np.nan
    c["data"]["points"] = points
    c.write(str(tmp / "no_LFHD.c3d"))
    return tmp / "no_LFHD.c3d"


def _as_qualisys(tmp: Path) -> Path:
    """The real full-body capture with its labels renamed to the Qualisys sports marker set."""
    c = ezc3d.c3d(str(FULL))
    rename = {k: v.split("|")[0] for k, v in QUALISYS_SPORTS.items() if k != "STRN"}
    rename.update({"LFHD": "HeadL", "RFHD": "HeadR", "LBHD": "HeadTop", "RBHD": "HeadFront"})
    labels = [rename.get(k.strip(), k.strip() + "_x") for k in c["parameters"]["POINT"]["LABELS"]["value"]]
    c["parameters"]["POINT"]["LABELS"]["value"] = labels
    c.write(str(tmp / "qualisys_sports.c3d"))
    return tmp / "qualisys_sports.c3d"


#: file -> None (curves) or the one-line refusal expected
MUST_SHOW = {
    "PiG_Calibration-FlatFoot-Full.c3d": None,
    "no_LFHD.c3d": None,
    "qualisys_sports.c3d": None,
    "PiG_Calibration3_FF.c3d": "expected a full-body Plug-in Gait marker set, found the lower body only",
    "PlugInC3D.c3d": "expected the Plug-in Gait markers CLAV, LSHO, RSHO, LELB, RELB, LWRA, LWRB, RWRA, RWRB, LFIN, "
                     "RFIN (see docs: effortface.synth.c3d_marker_sets), found RKNE, RTOE,",
    # long occlusions: read over their longest complete window (2.2 s, 5.9 s), then unmapped labelled points
    "type-2a.c3d": "skeleton joints: expected every segment mapped",
    "Eb015pi.c3d": "skeleton joints: expected every segment mapped",
    "sample21.c3d": "skeleton joints: expected every segment mapped",
    "MACsample.c3d": "skeleton joints: expected every segment mapped",
}


@pytest.mark.parametrize("name", list(MUST_SHOW))
def test_synth_on_real_files(tmp_path, name):
    clip = {"no_LFHD.c3d": _without_lfhd, "qualisys_sports.c3d": _as_qualisys}.get(name, lambda _: DATA / name)(tmp_path)
    out = tmp_path / "face.csv"
    done = _synth(clip, out)
    expected = MUST_SHOW[name]
    if expected is None:
        assert done.returncode == 0, done.stderr
        table = np.genfromtxt(out, delimiter=",", names=True)
        assert len(table) > 50 and all(np.isfinite(table[c]).all() for c in table.dtype.names)
        provenance = json.loads(out.with_name("face.units.json").read_text())["motion"]
        assert f"gaps of at most {MAX_GAP_S:g} s linearly interpolated" in provenance
        if name == "no_LFHD.c3d":
            assert "head from RFHD, LBHD, RBHD (LFHD left out)" in provenance
    else:
        assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
        assert len(done.stderr.strip().splitlines()) == 1 and expected in done.stderr, done.stderr
        assert not out.exists()


def test_per_point_and_padded_units():
    assert units_per_point(Path("x"), ["mm  mm  mm"], 3).tolist() == [0.001] * 3
    assert units_per_point(Path("x"), ["mm", "cm", "m"], 3).tolist() == [0.001, 0.01, 1.0]
    assert units_per_point(Path("x"), ["mm\x00\x00"], 2).tolist() == [0.001] * 2
    with pytest.raises(MotionFormatError, match=r"POINT:UNITS: expected one of mm, cm, m, in.*found 'furlong'"):
        units_per_point(Path("x"), ["mm", "furlong"], 2)
    points = read_c3d_points(DATA / "sample21.c3d")          # POINT:UNITS 'mm\0\0' in the file
    height = points.positions_m[..., 2][~points.missing]
    assert 0.0 < np.median(height) < 1.5                      # metres: legs markers of a person


def test_short_gaps_filled_long_gaps_refused_naming_the_point():
    points = read_c3d_points(FULL)
    i = points.labels.index("LKNE")
    truth = points.positions_m[:, i].copy()
    short = points.missing.copy()
    short[40:50, i] = True                                     # 0.1 s at 100 Hz
    filled = fill_gaps(FULL, dataclasses.replace(points, missing=short), ["LKNE", "RKNE"])
    assert "linearly interpolated (10 point-frames)" in filled.note
    assert np.abs(filled.positions_m[40:50, 0] - truth[40:50]).max() < 0.02     # close to the real path
    long = short.copy()
    long[60:85, i] = True                                      # 0.25 s
    long[10:13, points.labels.index("RKNE")] = True            # another point's gaps are not counted in
    with pytest.raises(MotionFormatError) as err:         # 0.94 s of capture: no 1 s window to keep
        fill_gaps(FULL, dataclasses.replace(points, missing=long), ["LKNE", "RKNE"])
    assert str(err.value) == (f"{FULL}: point 'LKNE': expected every needed marker present (gaps up to 0.2 s filled) "
                              "over at least 1 s, found 'LKNE' missing in 35 of 94 frames, a gap of 25 frames from "
                              "frame 60; the longest complete window is 60 frames (0.60 s from frame 0); fill the gaps "
                              "in the capture software")


def test_head_from_three_markers_is_close_to_four():
    points = read_c3d_points(FULL)
    m = {k: points.positions_m[:, points.labels.index(k)] for k in HEAD_MARKERS}
    four = head_centre(m)
    for left_out in HEAD_MARKERS:
        three = head_centre({k: v for k, v in m.items() if k != left_out})
        assert np.linalg.norm(three - four, axis=1).max() < 0.025  # measured 2.1 cm: near a parallelogram
    assert head_centre({k: m[k] for k in HEAD_MARKERS[:2]}) is None


def test_qualisys_sports_set_gives_the_plug_in_gait_skeleton(tmp_path):
    pig, qualisys = read_c3d(FULL), read_c3d(_as_qualisys(tmp_path))
    assert qualisys.joint_names == pig.joint_names and "Qualisys sports markers" in qualisys.source
    hips = pig.joint_names.index("LeftUpLeg")
    np.testing.assert_allclose(qualisys.positions_m[:, hips], pig.positions_m[:, hips], atol=1e-6)


def test_readers_fallback_and_motion_analysis_quirk():
    assert read_c3d_points(FULL).notes[0] == "read with ezc3d"     # the c3d package refuses this Vicon file
    mac = read_c3d_points(DATA / "MACsample.c3d")                   # SGI/MIPS: ezc3d refuses, c3d reads
    assert mac.notes[0] == "read with the c3d package"
    assert any(n.startswith("header scale factor") and "ignored for POINT:SCALE" in n for n in mac.notes)
    assert np.isfinite(mac.positions_m).all() and np.abs(mac.positions_m[~mac.missing]).max() < 10.0   # metres


def test_attached_plug_in_gait_clip_gives_work(tmp_path):
    """A sample-lab session with the real Plug-in Gait C3D attached: `effortface work` takes its seconds."""
    import shutil

    src = Path(__file__).resolve().parents[2] / "sample_sessions" / "P01_20260112-093000_cardio"
    session = tmp_path / src.name
    shutil.copytree(src, session, ignore=shutil.ignore_patterns("video.avi", "serial"))
    run = lambda *a: subprocess.run([sys.executable, "-m", "effortface", *map(str, a)], capture_output=True,
                                    text=True, timeout=600)
    done = run("motion", "attach", session, FULL, "--offset", "30")
    assert done.returncode == 0, done.stderr
    done = run("work", session)
    assert done.returncode == 0, done.stderr
    rows = (session / "work.csv").read_text().splitlines()
    motion = [r for r in rows if r.endswith(f"motion:{FULL.name}")]
    assert motion and all(np.isfinite(float(r.split(",")[1])) for r in motion)
