"""C3D files as other labs write them (issue 34): the up axis from the file (``POINT:Y_SCREEN``,
checked against the markers), CAST/ISB landmark names, OptiTrack-style prefixed labels named as the
file has them, and a trial trimmed to a walkway read over its longest complete window. Real files
from tests/data/c3d (README.md there), rewritten with ezc3d where a variant is needed."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from effortface.synth.c3d_marker_sets import CAST_ISB, decide_up, match_names, up_rotation
from effortface.synth.c3d_motion import read_c3d, read_c3d_points
from effortface.synth.motion import MotionFormatError, read_motion
from effortface.synth.read_options import UP_AXES

DATA = Path(__file__).resolve().parents[1] / "data" / "c3d"
FULL = DATA / "PiG_Calibration-FlatFoot-Full.c3d"
WALK = DATA / "walking5.c3d"
QTM = DATA / "QTM_CGM2_Gait.c3d"
ezc3d = pytest.importorskip("ezc3d")

#: file -> its up axis written in: rows are the file's axes in the original's (a proper rotation:
#: file x = -x, file y = z, file z = y), so the Y-up copy is the Z-up capture turned a quarter about Z
Z_UP_TO_FILE = np.array([[-1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]])


def _rewrite(tmp: Path, name: str, *, rotate: np.ndarray | None = None, screen: tuple[str, str] | None = None,
             rename: dict[str, str] | None = None, source: Path = FULL) -> Path:
    """A real full-body file (the Vicon one unless told) rewritten by ezc3d: points rotated,
    POINT:X_SCREEN/Y_SCREEN set, labels renamed."""
    c = ezc3d.c3d(str(source))
    if rotate is not None:
        pts = c["data"]["points"]
        pts[:3] = np.einsum("ij,jpt->ipt", rotate, pts[:3])
        c["data"]["points"] = pts
    if screen is not None:
        c["parameters"]["POINT"]["X_SCREEN"]["value"] = [screen[0]]
        c["parameters"]["POINT"]["Y_SCREEN"]["value"] = [screen[1]]
    if rename is not None:
        labels = [k.strip() for k in c["parameters"]["POINT"]["LABELS"]["value"]]
        c["parameters"]["POINT"]["LABELS"]["value"] = [rename.get(k, k) for k in labels]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        c.write(str(tmp / name))
    return tmp / name


def _synth(clip: Path, out: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "effortface", "synth", "default", str(clip), "--out", str(out)],
                          capture_output=True, text=True, timeout=600)


def test_up_rotations_are_proper_and_turn_the_axis_up() -> None:
    for up in UP_AXES:
        rot = up_rotation(up)
        axis = np.zeros(3)
        axis["xyz".index(up[-1])] = -1.0 if up.startswith("-") else 1.0
        assert np.isclose(np.linalg.det(rot), 1.0) and np.allclose(rot @ rot.T, np.eye(3))  # never a reflection
        np.testing.assert_allclose(rot @ axis, [0.0, 0.0, 1.0])


@pytest.mark.parametrize("source", [FULL, QTM], ids=["vicon", "qtm"])
def test_a_y_up_file_gives_the_same_curves_as_the_z_up_original(tmp_path: Path, source: Path) -> None:
    """Must show: a real Z-up capture (Vicon Nexus; Qualisys QTM, Plug-in Gait, the issue's case)
    rotated to Y up with POINT:Y_SCREEN +Y (X_SCREEN -X, where the original's +X now lies) reads Y up
    and gives the original's curves within 1 %."""
    y_up = _rewrite(tmp_path, "y_up.c3d", rotate=Z_UP_TO_FILE, screen=("-X", "+Y"), source=source)
    original, turned = read_c3d(source), read_c3d(y_up)
    assert turned.reading["up_axis"] == "y" and turned.reading["up_from"] == "POINT:Y_SCREEN +Y (the markers agree)"
    assert original.reading["up_axis"] == "z"
    np.testing.assert_allclose(turned.positions_m[..., 2], original.positions_m[..., 2], atol=1e-5)   # heights kept
    height = np.ptp(turned.positions_m[..., 2], axis=1)
    assert 1.3 < np.median(height) < 1.9                                    # standing, not lying on its side
    curves = {}
    for name, clip in (("z", source), ("y", y_up)):
        out = tmp_path / f"{name}.csv"
        done = _synth(clip, out)
        assert done.returncode == 0, done.stderr
        curves[name] = np.genfromtxt(out, delimiter=",", names=True)
    z, y = curves["z"], curves["y"]
    assert len(z) == len(y) > 50
    for col in z.dtype.names:
        scale = max(np.abs(z[col]).max(), 1e-9)
        assert np.abs(y[col] - z[col]).max() <= 0.01 * scale, col


def test_read_as_the_caller_says_and_wrongly_told_is_lying_down(tmp_path: Path) -> None:
    y_up = _rewrite(tmp_path, "y_up.c3d", rotate=Z_UP_TO_FILE, screen=("-X", "+Y"))
    told = read_c3d(y_up, up="y")
    assert told.reading["up_from"] == "--up"
    wrong = read_c3d(y_up, up="z")                                          # the old reader's reading
    assert np.median(np.ptp(wrong.positions_m[..., 2], axis=1)) < 0.9
    assert np.median(np.ptp(told.positions_m[..., 2], axis=1)) > 1.3


def test_the_markers_decide_when_the_file_is_silent_or_contradicted(tmp_path: Path) -> None:
    """QTM 2.17 writes POINT:Y_SCREEN -Z on Z-up captures (measured on a real Qualisys file): the
    markers, head above feet along +z, win and the disagreement is stated."""
    contradicted = read_c3d(_rewrite(tmp_path, "minus_z.c3d", screen=("-X", "-Z")))
    assert contradicted.reading["up_axis"] == "z"
    assert contradicted.reading["up_from"] == "markers: head above feet along +z (POINT:Y_SCREEN -Z disagrees)"
    upside_down = _rewrite(tmp_path, "down.c3d", rotate=np.diag([1.0, -1.0, -1.0]), screen=("+X", "-Z"))
    down = read_c3d(upside_down)
    assert down.reading["up_axis"] == "-z" and down.reading["up_from"].startswith("POINT:Y_SCREEN -Z (the markers agree")
    np.testing.assert_allclose(down.positions_m[..., 2], read_c3d(FULL).positions_m[..., 2], atol=1e-5)
    assert decide_up(None, "", "-y") == ("-y", "markers: head above feet along -y (no POINT:Y_SCREEN)")
    assert decide_up(None, "", None)[0] == "z"


def test_a_real_qtm_export_is_read_upright_with_or_without_its_head() -> None:
    """Real Qualisys QTM 2019 Plug-in Gait trial: X_SCREEN -X, Y_SCREEN -Z on a Z-up capture (as
    in all 21 QTM files measured). The markers overrule it; a file without head and foot markers
    takes a negative Y_SCREEN's axis upwards, so it is not read upside down either."""
    qtm = read_c3d(QTM)
    assert qtm.reading["up_from"] == "markers: head above feet along +z (POINT:Y_SCREEN -Z disagrees)"
    assert qtm.reading["producer"] == "Qualisys Qualisys Track Manager 2019.4.4898"
    assert 1.5 < np.median(np.ptp(qtm.positions_m[..., 2], axis=1)) < 1.9
    axis, how = decide_up(None, "-Z", None)
    assert axis == "z" and how.startswith("POINT:Y_SCREEN -Z: its axis, upwards")
    assert decide_up(None, "+Y", None) == ("y", "POINT:Y_SCREEN +Y")


def test_reading_says_unit_producer_and_marker_set() -> None:
    reading = read_motion(FULL).reading
    assert reading["unit_m"] == 0.001 and reading["unit_from"] == "POINT:UNITS mm"
    assert reading["producer"].startswith("Vicon Vicon Nexus")
    assert reading["marker_set"].startswith("plug-in-gait")
    assert reading["window"] == {"first_frame": 0, "n_frames": 94, "of_frames": 94, "why": "every needed marker present"}
    scaled = read_c3d(FULL, unit_m=0.002)                                   # --unit-m wins over POINT:UNITS
    assert scaled.reading["unit_from"].startswith("--unit-m")
    hips = scaled.joint_names.index("LeftUpLeg")                           # Bell's hip centre scales with the pelvis
    np.testing.assert_allclose(scaled.positions_m[:, hips], 2 * read_c3d(FULL).positions_m[:, hips], rtol=1e-6)


#: Plug-in Gait -> CAST/ISB names (Qualisys PAF, Visual3D) for the same places
TO_CAST = {"LASI": "L_IAS", "RASI": "R_IAS", "LPSI": "L_IPS", "RPSI": "R_IPS", "C7": "CV7", "CLAV": "SJN",
           "T10": "TV10", "STRN": "SXS", "LFHD": "L_HDF", "RFHD": "R_HDF", "LBHD": "L_HDB", "RBHD": "R_HDB",
           **{f"{s}{pig}": f"{s}_{cast}" for s in "LR" for pig, cast in
              {"SHO": "SAE", "ELB": "HLE", "WRA": "RSP", "WRB": "USP", "FIN": "HM2", "KNE": "FLE", "ANK": "FAL",
               "TOE": "FM2"}.items()}}


def test_cast_isb_landmarks_give_the_plug_in_gait_skeleton(tmp_path: Path) -> None:
    cast = read_c3d(_rewrite(tmp_path, "cast.c3d", rename=TO_CAST))
    pig = read_c3d(FULL)
    assert cast.reading["marker_set"].startswith("cast-isb") and "Bell et al. 1990" in cast.reading["marker_set"]
    assert cast.joint_names == pig.joint_names
    np.testing.assert_allclose(cast.positions_m, pig.positions_m, atol=1e-6)
    assert CAST_ISB["LKNEM"] == "L_FME" and CAST_ISB["LTOE"] == "L_FM2|L_FM1+L_FM5|L_FM1"


def test_cast_medial_landmarks_make_mid_point_centres() -> None:
    from effortface.synth.c3d_motion import MarkerSetOptions, joint_centres

    points = read_c3d_points(FULL)
    m = {k: points.positions_m[:, points.labels.index(k)] for k in TO_CAST}
    j = joint_centres(m)
    lateral = (m["LASI"] - m["RASI"]) / np.linalg.norm(m["LASI"] - m["RASI"], axis=1, keepdims=True)
    o = MarkerSetOptions()
    m["LKNEM"] = m["LKNE"] - lateral * 2 * (o.knee_width_m / 2 + o.marker_radius_m)   # the medial epicondyle
    with_medial = joint_centres(m)
    np.testing.assert_allclose(with_medial["LeftLeg"], j["LeftLeg"], atol=1e-9)      # the mid-point rule
    m["LKNEM"] = m["LKNE"] - lateral * 0.12                                          # a 12 cm knee
    np.testing.assert_allclose(joint_centres(m)["LeftLeg"], m["LKNE"] - lateral * 0.06, atol=1e-9)


def test_prefixed_labels_match_and_are_named_as_in_the_file(tmp_path: Path) -> None:
    """OptiTrack Motive prefixes: ``Skeleton:LASI`` and ``Skeleton_LASI`` match Plug-in Gait; two
    rigid bodies' ``Marker3`` keep their whole labels (before: ``Marker3_15``, not in the file)."""
    points = read_c3d_points(FULL)
    colon = read_c3d(_rewrite(tmp_path, "colon.c3d", rename={k: f"Skeleton:{k}" for k in points.labels}))
    under = read_c3d(_rewrite(tmp_path, "under.c3d", rename={k: f"Skeleton_{k}" for k in points.labels}))
    pig = read_c3d(FULL)
    for clip in (colon, under):
        assert clip.reading["marker_set"].startswith("plug-in-gait")
        np.testing.assert_allclose(clip.positions_m, pig.positions_m, atol=1e-6)
    assert match_names(["L_IAS", "Skel_L_IAS"])["L_IAS"] == "L_IAS"           # CAST's underscore is kept
    assert match_names(["251112_KUO_LASI"])["LASI"] == "251112_KUO_LASI"      # a Motive take prefix
    rigid = _rewrite(tmp_path, "rigid.c3d", rename={"LTHI": "ForearmL:Marker3", "RTHI": "ForearmR:Marker3"})
    names = read_c3d_points(rigid).labels
    assert "ForearmL:Marker3" in names and "ForearmR:Marker3" in names and not any("_" in n[-3:] for n in names)


def test_a_refusal_names_the_label_as_in_the_file(tmp_path: Path) -> None:
    c = ezc3d.c3d(str(FULL))
    labels = [k.strip() for k in c["parameters"]["POINT"]["LABELS"]["value"]]
    c["parameters"]["POINT"]["LABELS"]["value"] = [f"ForearmL:{k}" if k == "LKNE" else k for k in labels]
    pts = c["data"]["points"]
    pts[:3, labels.index("LKNE"), 30:70] = np.nan                           # 0.4 s: no 1 s window in 0.94 s
    c["data"]["points"] = pts
    c.write(str(tmp_path / "gap.c3d"))
    with pytest.raises(MotionFormatError) as err:
        read_c3d(tmp_path / "gap.c3d")
    message = str(err.value)
    assert message.startswith(f"{tmp_path / 'gap.c3d'}: point 'ForearmL:LKNE': expected every needed marker present")
    assert "the longest complete window is 30 frames (0.30 s from frame 0)" in message and "\n" not in message


def test_a_trial_trimmed_to_a_walkway_is_read_over_its_window() -> None:
    """Real OpenSim walking5 (Vicon Nexus): the knee landmarks are missing in 653 of 1103 frames;
    before, refused; now the 1.80 s where every marker is present are read, and said so."""
    motion = read_c3d(WALK)
    window = motion.reading["window"]
    assert (window["first_frame"], window["n_frames"], window["of_frames"]) == (463, 450, 1103)
    assert "'RLFC' is missing or in a gap over 0.2 s in 653 of 1103 frames" in window["why"]
    assert motion.n_frames == 450 and "kept frames 463-912 of 1103 (1.80 s of 4.41 s)" in motion.source
    assert motion.reading["producer"] == "Vicon Vicon Nexus 1.8.2.49787h"
    assert motion.reading["up_from"] == "POINT:Y_SCREEN +Z (the markers agree)"


def test_synth_states_the_window_on_stderr_and_in_units_json(shared_data: Path, tmp_path: Path) -> None:
    """A full-body clip (the CMU squats, labelled points with the CMU joint names) with a 0.25 s
    occlusion: synth reads the longest window after it, says so in one line and in .units.json."""
    from tests.synth.test_motion_c3d import write_c3d

    bvh = read_motion(shared_data / "motion" / "cmu_13_29_squats_120fps.bvh")
    clip = write_c3d(bvh, tmp_path / "squats.c3d", occlude=(40, 3), n_occluded=30)
    out = tmp_path / "face.csv"
    done = _synth(clip, out)
    assert done.returncode == 0, done.stderr
    expected = f"{clip}: read frames 70-{bvh.n_frames - 1} of {bvh.n_frames}: the longest window where every needed"
    assert done.stderr.strip().splitlines() == [done.stderr.strip()] and done.stderr.startswith(expected)
    provenance = json.loads((tmp_path / "face.units.json").read_text())["motion"]
    assert f"kept frames 70-{bvh.n_frames - 1} of {bvh.n_frames}" in provenance


#: the point labels of a real Qualisys QTM 2.17 export with the CAST/ISB set (ezc3d's test file
#: Qualisys.c3d, GPL: not copied here), in its order
QTM_CAST_LABELS = (
    "L_IAS", "L_IPS", "R_IPS", "R_IAS", "SNJ", "SXS", "TV8", "CV7", "R_SCAP", "L_HDF", "L_HDB", "R_HDB", "R_HDF",
    "L_FTC", "L_WAND1", "L_FLE", "L_FME", "L_FAX", "L_TTC", "L_WAND2", "L_FAL", "L_TAM", "L_FCC", "L_FM1", "L_FM5",
    "R_FTC", "R_WAND1", "R_FLE", "R_FME", "R_FAX", "R_TTC", "R_WAND2", "R_FAL", "R_TAM", "R_FCC", "R_FM1", "R_FM5",
    "L_HM5", "L_HM2", "L_UHE", "L_RSP", "L_WAND4", "L_HLE", "L_HME", "L_WAND3", "R_HM5", "R_HM2", "R_UHE", "R_RSP",
    "R_WAND4", "R_HLE", "R_HME", "R_WAND3", "L_SAJ", "R_SAJ")


def _qtm_cast_layout(tmp: Path) -> Path:
    """A file laid out as the real QTM CAST export (its 55 labels, ``X_SCREEN -X``, ``Y_SCREEN -Z``
    on a Z-up capture, MANUFACTURER Qualisys), its points made from the real Vicon capture: the
    landmarks at the Plug-in Gait markers of the same places, the medial epicondyles and malleoli
    where the Plug-in Gait rule puts the joint centre's mirror (so the centres must come out equal)."""
    from effortface.synth.c3d_motion import MarkerSetOptions

    points = read_c3d_points(FULL)
    m = {k: points.positions_m[:, points.labels.index(k)] for k in points.labels}
    o = MarkerSetOptions()
    lat = (m["LASI"] - m["RASI"]) / np.linalg.norm(m["LASI"] - m["RASI"], axis=1, keepdims=True)
    sho = (m["LSHO"] - m["RSHO"]) / np.linalg.norm(m["LSHO"] - m["RSHO"], axis=1, keepdims=True)
    xyz = {"L_IAS": m["LASI"], "R_IAS": m["RASI"], "L_IPS": m["LPSI"], "R_IPS": m["RPSI"], "SNJ": m["CLAV"],
           "SXS": m["STRN"], "TV8": m["T10"], "CV7": m["C7"], "R_SCAP": m["RBAK"], "L_HDF": m["LFHD"],
           "R_HDF": m["RFHD"], "L_HDB": m["LBHD"], "R_HDB": m["RBHD"]}
    for s, sign in (("L", 1.0), ("R", -1.0)):
        medial = -sign * lat
        xyz.update({f"{s}_FTC": m[f"{s}THI"], f"{s}_WAND1": m[f"{s}THI"], f"{s}_FLE": m[f"{s}KNE"],
                    f"{s}_FME": m[f"{s}KNE"] + medial * 2 * (o.knee_width_m / 2 + o.marker_radius_m),
                    f"{s}_FAX": m[f"{s}TIB"], f"{s}_TTC": m[f"{s}TIB"], f"{s}_WAND2": m[f"{s}TIB"],
                    f"{s}_FAL": m[f"{s}ANK"],
                    f"{s}_TAM": m[f"{s}ANK"] + medial * 2 * (o.ankle_width_m / 2 + o.marker_radius_m),
                    f"{s}_FCC": m[f"{s}HEE"], f"{s}_FM1": m[f"{s}TOE"] + 0.03 * medial,
                    f"{s}_FM5": m[f"{s}TOE"] - 0.03 * medial, f"{s}_HM5": m[f"{s}FIN"], f"{s}_HM2": m[f"{s}FIN"],
                    f"{s}_UHE": m[f"{s}WRB"], f"{s}_RSP": m[f"{s}WRA"], f"{s}_WAND4": m[f"{s}WRA"],
                    f"{s}_HLE": m[f"{s}ELB"],
                    f"{s}_HME": m[f"{s}ELB"] - sign * sho * 2 * (o.elbow_width_m / 2 + o.marker_radius_m),
                    f"{s}_WAND3": m[f"{s}ELB"], f"{s}_SAJ": m[f"{s}SHO"]})
    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [points.rate_hz]
    c["parameters"]["POINT"]["LABELS"]["value"] = list(QTM_CAST_LABELS)
    c["parameters"]["POINT"]["UNITS"]["value"] = ["mm"]
    c.add_parameter("POINT", "X_SCREEN", ["-X"])
    c.add_parameter("POINT", "Y_SCREEN", ["-Z"])
    c.add_parameter("MANUFACTURER", "COMPANY", ["Qualisys"])
    c.add_parameter("MANUFACTURER", "SOFTWARE", ["Qualisys Track Manager"])
    pts = np.ones((4, len(QTM_CAST_LABELS), len(points.positions_m)))
    pts[:3] = np.stack([xyz[k] for k in QTM_CAST_LABELS], axis=1).transpose(2, 1, 0) * 1000.0
    c["data"]["points"] = pts
    c.write(str(tmp / "qtm_cast.c3d"))
    return tmp / "qtm_cast.c3d"


def test_the_qualisys_cast_layout_reads_as_the_plug_in_gait_capture(tmp_path: Path) -> None:
    """The real QTM CAST export's layout (measured: a standing height of 1.51 m, Z up by its
    markers): the same joint centres as Plug-in Gait's rules on the same capture, its Y_SCREEN -Z
    overruled by the markers, its producer read."""
    clip = read_c3d(_qtm_cast_layout(tmp_path))
    pig = read_c3d(FULL)
    assert clip.reading["marker_set"].startswith("cast-isb")
    assert clip.reading["up_axis"] == "z" and "POINT:Y_SCREEN -Z disagrees" in clip.reading["up_from"]
    assert clip.reading["producer"] == "Qualisys Qualisys Track Manager"
    np.testing.assert_allclose(clip.positions_m, pig.positions_m, atol=1e-5)


def test_labelled_points_without_y_screen_are_turned_by_their_head_and_feet(shared_data: Path, tmp_path: Path) -> None:
    """A Y-up export of labelled joints (the CMU squats' joint names) with no POINT:Y_SCREEN: the
    Head is above the feet along +y, so it is read Y up."""
    from tests.synth.test_motion_c3d import write_c3d

    bvh = read_motion(shared_data / "motion" / "cmu_13_29_squats_120fps.bvh")
    file_frame = Z_UP_TO_FILE                                               # Z up -> the file's Y up
    y_up = write_c3d(dataclasses.replace(bvh, positions_m=bvh.positions_m @ file_frame.T, rotations=None),
                     tmp_path / "y_up.c3d")
    clip = read_c3d(y_up)
    assert clip.reading["up_axis"] == "y"
    assert clip.reading["up_from"] == "markers: head above feet along +y (no POINT:Y_SCREEN)"
    np.testing.assert_allclose(clip.positions_m[..., 2], bvh.positions_m[..., 2], atol=1e-4)
