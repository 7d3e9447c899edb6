"""The exercise log vocabulary: phases and their parameters over time, old sessions still readable."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from effortface.core.session.folder import EVENTS_HEADER
from effortface.core.errors import SessionFormatError
from effortface.synth.exercise_log import exercise_id, read_exercise_log

SAMPLES = Path(__file__).resolve().parents[2] / "sample_sessions"


def _events(tmp_path: Path, rows: list[str]) -> Path:
    path = tmp_path / "events.csv"
    path.write_text("\n".join([EVENTS_HEADER, *rows]) + "\n", encoding="utf-8")
    return path


def test_phases_parameters_and_loads_over_time(tmp_path: Path) -> None:
    path = _events(tmp_path, [
        "0,sync,jump,", "1,load,back_kg,10",
        "5,phase_start,treadmill,", "5,speed,treadmill,1.5", "5,grade,treadmill,2",
        "35,speed,treadmill,3.0", "60,phase_end,treadmill,",
        "70,phase_start,squats,", "70,load,left_kg,5", "100,reps,squats,10", "100,phase_end,squats,",
        "110,phase_start,treadmill,",  # never ended: runs to the end of the session
    ])
    log = read_exercise_log(path)
    assert [(p.exercise, p.start_s, p.end_s) for p in log.phases] == [
        ("treadmill", 5.0, 60.0), ("squats", 70.0, 100.0), ("treadmill", 110.0, math.inf)]
    pieces = log.states(log.phases[0])
    assert [(a, b, s.speed_m_s, s.grade_pct) for a, b, s in pieces] == [(5, 35, 1.5, 2.0), (35, 60, 3.0, 2.0)]
    assert pieces[0][2].load_kg("back_kg") == 10 and pieces[0][2].load_kg("left_kg") == 0
    (_, _, squat), = log.states(log.phases[1])
    assert squat.reps_per_min == pytest.approx(20.0)  # 10 reps in 30 s
    assert squat.load_kg("back_kg") == 10 and squat.load_kg("left_kg") == 5  # loads hold until changed
    (_, _, later), = log.states(log.phases[2])
    assert later.speed_m_s == 3.0  # the treadmill keeps its speed across phases


#: rows of the sample lab of earlier releases, before it was regenerated in the catalog's vocabulary:
#: P01's cardio session verbatim (less two link rows), then a jumping-jacks set as its strength session
#: logged one (there at 130-175 s)
EARLIER_LAB_ROWS = [
    "0.0000,sync,session_start,", "0.0000,phase_start,walk 1.5 m/s,4.20", "0.0000,speed,treadmill_m_s,1.5",
    "0.2414,link,tracking,ant", "24.9900,phase_end,walk 1.5 m/s,", "25.0000,phase_start,run 2.5 m/s,15.00",
    "25.0000,speed,treadmill_m_s,2.5", "69.9900,phase_end,run 2.5 m/s,", "70.0000,phase_start,walk 1.2 m/s,3.36",
    "70.0000,speed,treadmill_m_s,1.2", "104.9900,phase_end,walk 1.2 m/s,", "105.0000,phase_start,run 3.4 m/s,20.40",
    "105.0000,speed,treadmill_m_s,3.4", "149.9900,phase_end,run 3.4 m/s,", "150.0000,phase_start,rest,0.10",
    "199.9900,phase_end,rest,", "200.0000,phase_start,jumping jacks,8.60", "244.5000,reps,jumping jacks,50",
    "244.9900,phase_end,jumping jacks,",
]


def test_sessions_of_earlier_releases_stay_readable(tmp_path: Path) -> None:
    """The earlier sample lab's logs: 'walk 1.5 m/s' labels, 'treadmill_m_s' speeds, 'jumping jacks'."""
    log = read_exercise_log(_events(tmp_path, EARLIER_LAB_ROWS))
    assert [p.exercise for p in log.phases] == ["treadmill_walk", "treadmill_run", "treadmill_walk",
                                                "treadmill_run", "rest", "jumping_jacks"]
    (_, _, state), = log.states(log.phases[1], ("treadmill",))
    assert state.speed_m_s == 2.5
    assert exercise_id("Jumping Jacks") == exercise_id("jumping-jacks") == "jumping_jacks"


def test_the_sample_lab_logs_in_the_catalog_vocabulary() -> None:
    """The regenerated sample lab: catalog ids, treadmill speed / grade rows, back loads, reps."""
    cardio = read_exercise_log(SAMPLES / "P01_20260112-093000_cardio")
    assert {p.exercise for p in cardio.phases} == {"rest", "treadmill"}
    speeds = [cardio.states(p)[-1][2].speed_m_s for p in cardio.phases if p.exercise == "treadmill"]
    assert speeds[:2] == [1.5, 2.5]
    strength = read_exercise_log(SAMPLES / "P02_20260112-113700_strength")
    assert {p.exercise for p in strength.phases} == {"rest", "jumping_jacks", "squats"}
    squats = [p for p in strength.phases if p.exercise == "squats"]
    loaded = strength.states(squats[0])[-1][2]
    assert loaded.load_kg("back_kg") == 20 and 18 < loaded.reps_per_min < 24


def test_the_capture_stage_values_of_earlier_releases(tmp_path: Path) -> None:
    """``load_kg=5;speed_kmh=7.2`` on phase_start and on load rows labelled with the phase."""
    log = read_exercise_log(_events(tmp_path, ["0,phase_start,treadmill,load_kg=0;speed_kmh=7.2",
                                               "30,load,treadmill,load_kg=10;speed_kmh=10.8",
                                               "60,phase_end,treadmill,", "60,phase_start,recovery,"]))
    (_, _, first), (_, _, second) = log.states(log.phases[0])
    assert first.speed_m_s == pytest.approx(2.0) and second.speed_m_s == pytest.approx(3.0)
    assert second.load_kg("machine_kg") == 10


BAD_LOGS = {
    r"line 3: speed treadmill: expected a number >= 0 m/s, found '-1'": ["0,phase_start,treadmill,",
                                                                        "0,speed,treadmill,-1"],
    r"line 2: load back_kg: expected a number >= 0 kg, found '-5'": ["0,load,back_kg,-5"],
    r"line 2: load label: expected one of back_kg, left_kg, right_kg, machine_kg, found 'head_kg'":
        ["0,load,head_kg,5"],
    r"line 2: power cycle_ergometer: expected a number >= 0 W, found 'fast'": ["0,power,cycle_ergometer,fast"],
    r"line 2: speed exercise: expected a number >= 0 m/s, found '-3'": ["0,phase_start,exercise,load_kg=1;speed_kmh=-3"],
    r"line 3: phase_end 'squats': expected the end of an open phase of that exercise, found phase 'rest' open":
        ["0,phase_start,rest,", "5,phase_end,squats,"],
}


@pytest.mark.parametrize(("message", "rows"), BAD_LOGS.items(), ids=range(len(BAD_LOGS)))
def test_bad_logs_name_the_file_and_line(tmp_path: Path, message: str, rows: list[str]) -> None:
    path = _events(tmp_path, rows)
    with pytest.raises(SessionFormatError, match=f"^{path}: " + message):
        read_exercise_log(path)


def test_a_parameter_logged_a_moment_late_applies_from_the_phase_start(tmp_path: Path) -> None:
    """The recorder writes phase_start, then the plan's speed a fraction of a millisecond later."""
    log = read_exercise_log(_events(tmp_path, ["0.0031,phase_start,treadmill,", "0.0032,speed,treadmill,1.5",
                                               "20,speed,treadmill,3"]))
    pieces = log.states(log.phases[0])
    assert [(a, s.speed_m_s) for a, _, s in pieces] == [(0.0031, 1.5), (0.0032, 1.5), (20.0, 3.0)]


def test_grade_may_be_negative_and_a_missing_file_is_an_empty_log(tmp_path: Path) -> None:
    log = read_exercise_log(_events(tmp_path, ["0,phase_start,treadmill,", "0,grade,treadmill,-3"]))
    assert log.states(log.phases[0])[0][2].grade_pct == -3
    assert read_exercise_log(tmp_path / "nothing").phases == []
