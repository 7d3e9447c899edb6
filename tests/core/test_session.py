"""The session format: participant rules, ids, session.json round trip, CSV readers, validation."""

from __future__ import annotations

import datetime as dt
import json

import pytest

from effortface.core.errors import SessionFormatError, UserError
from effortface.capture_tool.protocols import HrSample
from effortface.core.session.folder import (
    Event,
    EventWriter,
    FrameTimeWriter,
    HrWriter,
    Participant,
    SessionInfo,
    create_session,
    list_sessions,
    make_session_id,
    parse_session_id,
    read_session,
    read_session_info,
    validate_session,
)

WHEN = dt.datetime(2026, 3, 4, 5, 6, 7)


def _info(code: str = "P01", label: str | None = None) -> SessionInfo:
    p = Participant("P01" if code is None else code, "f", 31, 1.68, 61.5, 4.0, hr_rest_bpm=58)
    return SessionInfo(make_session_id(p.code, WHEN, label), p, {"heart_rate": {"protocol": "hxm"}},
                       created_utc="2026-03-04T04:06:07Z", software={"name": "effortface"})


@pytest.mark.parametrize("code", ["P01", "LAB2-07", "S123"])
def test_participant_code_accepted(code: str) -> None:
    assert Participant(code).code == code


@pytest.mark.parametrize(
    ("match", "kwargs"),
    [
        ("codes, never names", {"code": "Jane Doe"}),
        ("codes, never names", {"code": "jane"}),
        ("codes, never names", {"code": "JANE"}),  # no digit: looks like a name
        ("codes, never names", {"code": "p01"}),
        ("sex: expected one of female, male", {"code": "P01", "sex": "x"}),
        ("age: expected a number from 10 to 100 years", {"code": "P01", "age": 400}),
        ("height_m: expected a number from 0.5 to 2.6 m", {"code": "P01", "height_m": 178}),
        ("mass_kg", {"code": "P01", "mass_kg": -1}),
        ("training_level", {"code": "P01", "training_level": 11}),
        ("hr_rest_bpm: expected below hr_max_bpm", {"code": "P01", "hr_rest_bpm": 110, "hr_max_bpm": 105}),
    ],
)
def test_participant_rejects(match: str, kwargs: dict) -> None:
    with pytest.raises(UserError, match=match):
        Participant(**kwargs)


def test_sex_aliases_normalised() -> None:
    assert Participant("P01", sex="M").sex == "male"


def test_session_id_round_trip() -> None:
    sid = make_session_id("P07", WHEN, "treadmill")
    assert sid == "P07_20260304-050607_treadmill"
    assert parse_session_id(sid) == ("P07", WHEN, "treadmill")
    assert parse_session_id("P07_20260304-050607") == ("P07", WHEN, None)
    with pytest.raises(UserError, match="session label"):
        make_session_id("P07", WHEN, "bad label")
    with pytest.raises(UserError, match="session id: expected"):
        parse_session_id("Jane_2026")


def test_session_save_read_round_trip(tmp_path) -> None:
    info = _info(label="run")
    info.extra["stats"] = {"hr_samples": 3}
    folder = create_session(tmp_path, info)
    assert folder.name == "P01_20260304-050607_run" and (folder / "serial").is_dir()
    back = read_session_info(folder)
    assert back == info
    assert json.loads((folder / "session.json").read_text())["complete"] is False


def test_session_overwrite_refused(tmp_path) -> None:
    folder = create_session(tmp_path, _info())
    with pytest.raises(FileExistsError):
        create_session(tmp_path, _info())  # same folder: never reused
    with pytest.raises(FileExistsError, match="refusing to overwrite"):
        _info().save(folder)
    for writer in (EventWriter, FrameTimeWriter, HrWriter):
        path = folder / f"{writer.__name__}.csv"
        writer(path).close()
        path.write_text(path.read_text() + "x\n")
        with pytest.raises(FileExistsError):
            writer(path)


def test_full_session_round_trip(tmp_path) -> None:
    info = _info()
    folder = create_session(tmp_path, info)
    samples = [HrSample(0.5, 72.0, (830.0,), 5, "hxm", True), HrSample(1.25, None, (), 6, "hxm", False)]
    events = [Event(0.0, "phase_start", "rest"), Event(2.5, "marker", "a, \"quoted\" label", "3")]
    hr, ev, fr = HrWriter(folder / "heart_rate.csv"), EventWriter(folder / "events.csv"), FrameTimeWriter(folder / "video_frames.csv")
    for s in samples:
        hr.write(s)
    for e in events:
        ev.write(e)
    for i, t in enumerate([0.01, 0.045, 0.08]):
        fr.write(i, t)
    for w in (hr, ev, fr):
        w.close()
    s = read_session(folder)
    assert s.heart_rate == samples and s.events == events and s.frame_times_s == [0.01, 0.045, 0.08]
    assert s.participant.code == "P01" and s.devices["heart_rate"]["protocol"] == "hxm"
    (folder / "video_frames.csv").unlink()  # no video.avi in this test: frame times alone are a problem
    assert validate_session(folder) == [f"{folder / 'session.json'}: complete is false (run 'effortface recover {folder}')"]
    info.complete = True
    info.save(folder, overwrite=True)
    assert validate_session(folder) == []
    assert list_sessions(tmp_path) == [folder]


@pytest.mark.parametrize(
    ("match", "name", "text"),
    [
        ("expected keys", "session.json", '{"session_id": "P01_20260304-050607"}'),
        ("expected JSON", "session.json", "{not json"),
        ("expected schema_version 1, found 2", "session.json", '{"schema_version": 2, "session_id": "x", "complete": false, "participant": {"code": "P01"}}'),
        ("codes, never names", "session.json", '{"schema_version": 1, "session_id": "x", "complete": false, "participant": {"code": "Ann Lee"}}'),
        ("expected header 't_s,kind,label,value'", "events.csv", "time,what\n"),
        ("line 2: expected t_s,kind,label,value", "events.csv", "t_s,kind,label,value\nabc,marker,,\n"),
        ("expected frame 1, found 2", "video_frames.csv", "frame,t_s\n0,0.1\n2,0.2\n"),
    ],
)
def test_bad_files_name_the_file(tmp_path, match: str, name: str, text: str) -> None:
    folder = create_session(tmp_path, _info())
    (folder / name).write_text(text)
    with pytest.raises(SessionFormatError, match=match) as err:
        read_session(folder)
    assert name in str(err.value)
    assert validate_session(folder)[0].startswith(str(folder / name))


def test_read_session_missing_folder(tmp_path) -> None:
    with pytest.raises(SessionFormatError, match="expected a session folder, found nothing"):
        read_session(tmp_path / "nope")
    with pytest.raises(SessionFormatError, match="expected a session.json"):
        read_session(tmp_path)
    with pytest.raises(UserError, match="expected a folder of sessions"):
        list_sessions(tmp_path / "nope")


def test_validate_finds_problems(tmp_path) -> None:
    info = _info()
    info.complete = True
    folder = create_session(tmp_path, info)
    (folder / "heart_rate.csv").write_text("t_s,hr_bpm,rr_ms,beat_count,device,valid\n1.0,0,,,x,1\n0.5,70,,,x,1\n")
    (folder / "video.avi").write_bytes(b"")
    problems = "\n".join(validate_session(folder))
    assert "t_s decreases 1 times" in problems
    assert "missing or non-positive hr_bpm" in problems
    assert "video.avi and video_frames.csv must be present together" in problems
