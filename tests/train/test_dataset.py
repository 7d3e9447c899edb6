"""Datasets: session folders and the long table -> per-second rows; bad inputs name file and problem."""

from __future__ import annotations

import gc
import json
import tracemalloc
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from effortface.core.blendshapes import DEFAULT_SET
from effortface.annotate.keyframes import KeyframeTrack
from effortface.core.errors import UserError
from effortface.train.dataset import (TABLE_COLUMNS, DatasetError, hr_series, prepare, read_table,
                           session_table, sessions_table, synthetic_table, write_table)
from effortface.synth.physiology import hr_max_bpm, hr_rest_bpm


@pytest.fixture(scope="module")
def table() -> pd.DataFrame:
    return synthetic_table(n_participants=3, seconds=120, seed=3)


@pytest.fixture
def lab(tmp_path: Path, table: pd.DataFrame, make_session) -> Path:
    for _, rows in table.groupby("session"):
        make_session(tmp_path, rows.reset_index(drop=True), raters={"R1": 0.0, "R2": 0.1})
    return tmp_path


def test_table_round_trip_and_refuses_overwrite(tmp_path, table):
    path = write_table(table, tmp_path / "t.csv")
    back = read_table(path, DEFAULT_SET)
    assert list(back.columns[: len(TABLE_COLUMNS)]) == list(TABLE_COLUMNS)
    np.testing.assert_allclose(back["hr_bpm"], table["hr_bpm"], rtol=1e-5)
    assert (back["exercise"] == table["exercise"]).all()
    with pytest.raises(FileExistsError, match="refusing to overwrite"):
        write_table(table, path)


def _held_by_read_and_prepare(path: Path) -> tuple[int, int]:
    """Bytes that tracemalloc sees held while the read table and its prepared frame are both alive
    (as the training run holds them), and the rows."""
    gc.collect()
    tracemalloc.start()
    try:
        table = read_table(path, DEFAULT_SET)
        prepared = prepare(table)
        gc.collect()
        held = tracemalloc.get_traced_memory()[0]
    finally:
        tracemalloc.stop()
    assert len(prepared) == len(table)
    return held, len(prepared)


def test_read_table_and_prepare_hold_little_per_row(tmp_path):
    """The memory the training table holds grows by under 200 bytes a row (read table + prepared
    frame, both alive), measured between 3,600 and 10,800 rows.

    Before: about 290 bytes a row (the participant, session, sex and exercise columns held as
    strings, 8-byte pointers a row in both frames, and a prepared copy of every float column);
    now about 135 (one-byte category codes, and the prepared frame shares the table's sorted
    columns and adds its four: HR_rest, HR_max, NHR, EPOC_norm).
    """
    small = write_table(synthetic_table(n_participants=2, seconds=900, seed=1), tmp_path / "small.csv")
    large = write_table(synthetic_table(n_participants=6, seconds=900, seed=1), tmp_path / "large.csv")
    _held_by_read_and_prepare(small)  # first calls: pandas' lazy imports and caches
    held_small, rows_small = _held_by_read_and_prepare(small)
    held_large, rows_large = _held_by_read_and_prepare(large)
    per_row = (held_large - held_small) / (rows_large - rows_small)
    assert 0 < per_row < 200, f"{per_row:.0f} bytes a row"


def test_text_columns_are_categoricals_that_sort_and_group_as_strings(tmp_path, table):
    """read_table holds the text columns as categoricals with sorted categories, and prepare gives
    the same frame for a shuffled table as for the sorted one without changing its input."""
    back = read_table(write_table(table, tmp_path / "t.csv"), DEFAULT_SET)
    for col in ("participant", "session", "sex", "exercise"):
        assert isinstance(back[col].dtype, pd.CategoricalDtype)
        assert list(back[col].cat.categories) == sorted(back[col].cat.categories)
        assert back[col].to_numpy(str).tolist() == table[col].astype(str).tolist()
    shuffled = back.sample(frac=1.0, random_state=0).reset_index(drop=True)
    before = shuffled.copy()
    pd.testing.assert_frame_equal(prepare(shuffled), prepare(back))
    pd.testing.assert_frame_equal(shuffled, before)
    text = {col: str for col in ("participant", "session", "sex", "exercise")}
    plain = prepare(shuffled.astype(text))  # the same rows with the text columns as strings
    pd.testing.assert_frame_equal(prepare(shuffled).astype(text), plain)


def test_sessions_give_per_second_rows_with_mean_of_raters(lab, table):
    got = sessions_table([lab])
    assert got["session"].nunique() == table["session"].nunique()
    one = got[got["session"] == got["session"].iloc[0]]
    assert np.all(np.diff(one["t_s"]) == 1.0)
    # key-frames every 5 s: at key times the weight is the rater mean, i.e. truth + 0.05 offset
    src = table[table["participant"] == one["participant"].iloc[0]]
    src = src[src["exercise"] == one["exercise"].iloc[0]].set_index("t_s")
    at_keys = one[one["t_s"] % 5 == 0].set_index("t_s")
    want = (np.clip(src.loc[at_keys.index, "eye_squint"], 0, 1)
            + np.clip(src.loc[at_keys.index, "eye_squint"] + 0.1, 0, 1)) / 2
    np.testing.assert_allclose(at_keys["eye_squint"], want, atol=1e-6)
    # HR: strap samples at t + 0.3 s interpolated back to whole seconds
    np.testing.assert_allclose(one["hr_bpm"].iloc[1:-1], src["hr_bpm"].iloc[1:len(one) - 1], atol=1.0)


def test_one_named_rater(lab):
    r1 = sessions_table([lab], rater_policy="R1")
    r2 = sessions_table([lab], rater_policy="R2")
    assert (r2["mouth_open"] >= r1["mouth_open"] - 1e-9).all()
    assert (r2["mouth_open"] - r1["mouth_open"]).max() == pytest.approx(0.1, abs=1e-6)


def test_prepare_uses_chart_and_measured_values(table):
    t = table.copy()
    prepared = prepare(t)
    row = prepared.iloc[0]
    assert row["hr_rest_bpm"] == pytest.approx(hr_rest_bpm(row["age"], row["sex"], row["training_level"]))
    assert row["hr_max_bpm"] == pytest.approx(hr_max_bpm(row["age"]))
    assert prepared["nhr"].between(0, 1).all() and (prepared["epoc_norm"] >= 0).all()
    t["hr_rest_bpm"], t["hr_max_bpm"] = 50.0, 200.0
    measured = prepare(t)
    np.testing.assert_allclose(measured["nhr"], ((measured["hr_bpm"] - 50) / 150).clip(0, 1))
    assert len(hr_series(measured)) == t["session"].nunique()


def _contradict(lab: Path) -> None:
    s = sorted(lab.glob("P01_*"))[1] / "session.json"
    doc = json.loads(s.read_text())
    doc["participant"]["age"] = doc["participant"]["age"] + 7
    s.write_text(json.dumps(doc))


def _no_hr(lab: Path) -> None:
    f = sorted(lab.glob("P02_*"))[0] / "heart_rate.csv"
    f.write_text("t_s,hr_bpm,rr_ms,beat_count,device,valid\n")


def _unannotated(lab: Path) -> None:
    for f in (sorted(lab.glob("P03_*"))[0] / "annotations").glob("*.json"):
        f.unlink()


@pytest.mark.parametrize("message, spoil, kwargs", [
    (r"participant P01: expected one age, found .* \(sessions P01_", _contradict, {}),
    (r"P02_.*heart_rate.csv: expected valid heart-rate samples, found 0", _no_hr, {}),
    (r"P03_.*: expected key-framed annotations \(annotations/<rater>.json\)", _unannotated, {}),
    (r"annotations: expected rater 'R9' \(--rater-policy\), found R1, R2", lambda lab: None,
     {"rater_policy": "R9"}),
])
def test_bad_sessions(lab, message, spoil, kwargs):
    spoil(lab)
    with pytest.raises(DatasetError, match=message):
        sessions_table([lab], **kwargs)


def _drop_col(df: pd.DataFrame) -> pd.DataFrame:
    return df.drop(columns=["hr_bpm"])


def _text_in_numbers(df: pd.DataFrame) -> pd.DataFrame:
    df = df.astype({"w_per_kg": object})
    df.loc[3, "w_per_kg"] = "fast"
    return df


def _two_sexes(df: pd.DataFrame) -> pd.DataFrame:
    df.loc[df["session"] == df["session"].iloc[-1], "sex"] = "female" if df["sex"].iloc[-1] == "male" else "male"
    return df


@pytest.mark.parametrize("message, spoil", [
    (r"t.csv: expected columns hr_bpm \(long format", _drop_col),
    (r"t.csv: column w_per_kg: expected numbers, found 'fast'", _text_in_numbers),
    (r"t.csv: participant P03: expected one sex, found", _two_sexes),
])
def test_bad_tables(tmp_path, table, message, spoil):
    path = tmp_path / "t.csv"
    spoil(table.copy()).to_csv(path, index=False)
    with pytest.raises(DatasetError, match=message):
        read_table(path, DEFAULT_SET)


def test_table_without_heart_rate_in_a_session(table):
    t = table.copy()
    t.loc[t["session"] == t["session"].iloc[0], "hr_bpm"] = np.nan
    with pytest.raises(DatasetError, match=r"session P01_.*: expected heart-rate values \(hr_bpm\), found none"):
        prepare(t, source="lab.csv")


def test_missing_folder_is_a_user_error(tmp_path):
    with pytest.raises(UserError, match="nope: expected a folder of sessions, found nothing"):
        sessions_table([tmp_path / "nope"])


def test_work_from_a_motion_clip_when_there_is_no_work_log(tmp_path):
    """The sample lab's loaded-squat set ships as real CMU mocap: without work.csv, w comes from
    the clip through effortface.synth.energy and agrees with the exercise log within 25 % (SCIENCE.md 2)."""
    import shutil

    lab = Path(__file__).resolve().parents[2] / "sample_sessions"
    src = next((p.parent.parent for p in lab.glob("*/motion/motion.json")), None)
    if src is None:
        pytest.skip("sample_sessions/ has no session with motion/ yet")
    from effortface.synth.work import derive_work

    folder = Path(shutil.copytree(src, tmp_path / src.name))
    assert not (folder / "work.csv").exists()  # the sample lab records none, as a capture
    table = session_table(folder)
    derived = derive_work(folder, table["t_s"].to_numpy())
    from_clip = np.array([s.startswith("motion:") for s in derived.source])
    log_only = Path(shutil.copytree(src, tmp_path / "log_only" / src.name, ignore=shutil.ignore_patterns("motion")))
    by_log = derive_work(log_only, table["t_s"].to_numpy())
    assert from_clip.sum() >= 20 and {by_log.source[i] for i in np.flatnonzero(from_clip)} == {"log:squats"}
    # the clip's w agrees with the catalog's estimate of the same set from the log
    assert table["w_per_kg"][from_clip].mean() == pytest.approx(by_log.w_per_kg[from_clip].mean(), rel=0.25)
    # before the clip: the exercise log (rest), not 0 and not the clip
    assert derived.source[0] == "log:rest" and table["w_per_kg"].iloc[0] == pytest.approx(0.1)


def test_work_from_a_motion_clip_needs_mass_and_sex(tmp_path):
    """Without work.csv, a participant recorded without a mass is named with the session (it used
    to reach the segment model as None: 'mass_kg: expected a body mass above 0 kg, got None')."""
    import shutil

    lab = Path(__file__).resolve().parents[2] / "sample_sessions"
    src = next((p.parent.parent for p in lab.glob("*/motion/motion.json")), None)
    if src is None:
        pytest.skip("sample_sessions/ has no session with motion/ yet")
    folder = Path(shutil.copytree(src, tmp_path / src.name))
    info = json.loads((folder / "session.json").read_text())
    del info["participant"]["mass_kg"]
    (folder / "session.json").write_text(json.dumps(info))
    # derived as `effortface work` does: the exercise log's seconds need the mass first
    with pytest.raises(DatasetError, match=rf"{src.name}/events.csv: expected the participant's mass_kg in "
                                           r"session.json to estimate work from the exercise log, found none"):
        session_table(folder)


def test_no_work_at_all(lab):
    folder = sorted(lab.glob("P01_*"))[0]
    (folder / "work.csv").unlink()
    with pytest.raises(DatasetError, match=r"P01_\S+: expected a motion/ folder \(motion.json\) or exercise "
                                           r"phases \(phase_start rows in events.csv\) to derive work, found neither"):
        session_table(folder)


def test_an_impossible_valid_sample_is_refused_before_interpolation(lab):
    """Issue 17 case 6: -70 bpm between two plausible samples became 50.8 bpm after 1 Hz interpolation."""
    f = sorted(lab.glob("P02_*"))[0] / "heart_rate.csv"
    lines = f.read_text().splitlines()
    fields = lines[5].split(",")
    fields[1] = "-70"
    lines[5] = ",".join(fields)
    f.write_text("\n".join(lines) + "\n")
    with pytest.raises(DatasetError, match=r"heart_rate.csv: line 6: expected hr_bpm from 25 to 250 on a valid "
                                           r"row, found -70"):
        sessions_table([lab])


def _half_finished(folder: Path, rater: str, name: str, passes_done: set[str] | None = None) -> None:
    """Replace one track of a rater's file by two keys at the start (the rater stopped there)."""
    from effortface.annotate.keyframes import read_annotations

    path = folder / "annotations" / f"{rater}.json"
    ann = read_annotations(path)
    ann.tracks[name] = KeyframeTrack()
    ann.tracks[name].add(0, 0.9)
    ann.tracks[name].add(20, 0.9)
    ann.passes_done = passes_done
    ann.save(path, overwrite=True)


def test_incomplete_tracks_are_left_out_of_every_rater_policy(lab):
    """Issue 16 item 7: 2 keys on one blendshape are not averaged in as a constant."""
    folder = sorted(p for p in lab.iterdir() if (p / "session.json").is_file())[0]
    before = session_table(folder)
    r1 = session_table(folder, rater_policy="R1")
    _half_finished(folder, "R2", "eye_squint")
    after = session_table(folder)
    np.testing.assert_allclose(after["eye_squint"], r1["eye_squint"])  # R1 alone: R2's stub is out
    assert not np.allclose(before["eye_squint"], after["eye_squint"])
    np.testing.assert_allclose(after["mouth_open"], before["mouth_open"])  # R2's complete tracks still count
    assert session_table(folder, rater_policy="R2")["eye_squint"].isna().all()


def test_a_track_without_its_finished_pass_is_left_out(lab):
    folder = sorted(p for p in lab.iterdir() if (p / "session.json").is_file())[0]
    from effortface.annotate.keyframes import read_annotations

    for rater in ("R1", "R2"):
        path = folder / "annotations" / f"{rater}.json"
        ann = read_annotations(path)
        ann.passes_done = {"mouth_stretch"}  # recorded passes: only mouth_stretch finished
        ann.save(path, overwrite=True)
    got = session_table(folder)
    assert got["mouth_stretch"].notna().all() and got[["mouth_open", "eye_squint", "brow_lower"]].isna().all().all()
    for rater in ("R1", "R2"):
        _half_finished(folder, rater, "mouth_stretch", set())
    with pytest.raises(DatasetError, match="expected complete key-frame tracks .*no gap over 30 s.*found none"):
        session_table(folder)
