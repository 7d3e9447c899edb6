"""``effortface capture --plan``, the participant registry, and a capture without heart rate."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

from effortface.capture_tool.participants import REGISTRY_TSV, read_registry
from effortface.capture_tool.plan import PlannedPhase, PlanRunner, read_plan
from effortface.core.session.folder import read_events, read_session
from effortface.cli import main

from .capture_helpers import BODY, effortface, hxm_chunks, start_replay, write_serlog

PLAN = """# a short protocol
start_s,end_s,exercise,speed_m_s,grade_pct,back_kg
0,2,rest,,,
2,4,squats,,,10
4,6,treadmill,1.5,2,0
"""


def _plan(tmp_path: Path, text: str = PLAN) -> Path:
    (tmp_path / "plan.csv").write_text(text, encoding="utf-8")
    return tmp_path / "plan.csv"


def test_plan_runner_logs_phases_parameters_and_a_countdown(tmp_path: Path) -> None:
    marked: list[tuple[float, str, str, str]] = []
    said: list[str] = []
    now = [0.0]
    runner = PlanRunner(read_plan(_plan(tmp_path)), lambda k, label, v: marked.append((now[0], k, label, v)),
                        said.append)
    for tick in range(0, 70):
        now[0] = tick / 10
        runner.step(now[0])
    assert runner.done and runner.end_s == 6
    assert [(t, k, label, v) for t, k, label, v in marked] == [
        (0.0, "phase_start", "rest", ""), (2.0, "phase_end", "rest", ""),
        (2.0, "phase_start", "squats", ""), (2.0, "load", "back_kg", "10"), (4.0, "phase_end", "squats", ""),
        (4.0, "phase_start", "treadmill", ""), (4.0, "speed", "treadmill", "1.5"), (4.0, "grade", "treadmill", "2"),
        (4.0, "load", "back_kg", "0"), (6.0, "phase_end", "treadmill", "")]
    assert "phase 2/3 squats 2 s (back_kg 10) starts in 1 s" in said and "squats: stop" in said


def test_a_stopped_capture_ends_the_open_phase() -> None:
    marked: list[tuple[str, str]] = []
    runner = PlanRunner([PlannedPhase(0, 60, "rest")], lambda k, label, v: marked.append((k, label)), lambda _: None)
    runner.step(1.0)
    runner.finish()
    assert marked == [("phase_start", "rest"), ("phase_end", "rest")]


def test_capture_with_a_plan_logs_it_and_work_follows(tmp_path: Path, shared_data: Path) -> None:
    """A real HxM stream replayed at 10x through a pseudo-terminal; the plan ends the capture."""
    replay, pty = start_replay(write_serlog(tmp_path / "strap.serlog", hxm_chunks(shared_data, 0, 30)),
                               "--speed", "10")
    done = subprocess.run(effortface("capture", "--port", pty, "--protocol", "hxm", "--participant", "P07", *BODY,
                                     "--no-video", "--plan", _plan(tmp_path), "--out", tmp_path / "lab"),
                          capture_output=True, text=True, timeout=60)
    replay.terminate()
    replay.wait(10)
    assert done.returncode == 0, done.stderr
    out = done.stdout.splitlines()
    session = Path(out[0])
    assert "phase 3/3 treadmill 2 s (speed_m_s 1.5, grade_pct 2, back_kg 0) starts in 1 s" in out
    kinds = [(e.kind, e.label, e.value) for e in read_events(session / "events.csv") if e.kind not in ("sync", "link")]
    assert kinds == [("phase_start", "rest", ""), ("phase_end", "rest", ""), ("phase_start", "squats", ""),
                     ("load", "back_kg", "10"), ("phase_end", "squats", ""), ("phase_start", "treadmill", ""),
                     ("speed", "treadmill", "1.5"), ("grade", "treadmill", "2"), ("load", "back_kg", "0"),
                     ("phase_end", "treadmill", "")]
    assert read_session(session).info.complete
    assert read_registry(tmp_path / "lab" / REGISTRY_TSV)["P07"].mass_kg == 60
    assert main(["work", str(session)]) == 0
    assert "log:treadmill" in (session / "work.csv").read_text()


def _capture(tmp_path: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run(effortface("capture", "--port", "loop://", "--protocol", "hxm", "--no-video",
                                     "--duration", "1", "--out", tmp_path / "lab", *args),
                          capture_output=True, text=True, timeout=60)


def test_the_registry_gives_the_demographics_once_entered(tmp_path: Path) -> None:
    first = _capture(tmp_path, "--participant", "P08", *BODY)
    assert first.returncode == 1  # loop:// sends no heart rate (see below); the session is kept
    registry = (tmp_path / "lab" / REGISTRY_TSV).read_text()
    assert registry == ("participant_id\tsex\tage\theight_m\tmass_kg\ttraining_level\thr_rest_bpm\thr_max_bpm\n"
                        "P08\tfemale\t30\t1.68\t60\t4\tn/a\tn/a\n")
    again = _capture(tmp_path, "--participant", "P08")
    session = Path(again.stdout.splitlines()[0])
    assert read_session(session).participant.height_m == 1.68
    assert (tmp_path / "lab" / REGISTRY_TSV).read_text() == registry  # not registered twice


def test_no_heart_rate_ends_with_a_warning_and_status_1(tmp_path: Path) -> None:
    done = _capture(tmp_path, "--participant", "P09", *BODY)
    assert done.returncode == 1
    assert re.fullmatch(r"warning: no heart-rate sample received from --port loop:// \(--protocol hxm\): 0 "
                        r"heart-rate samples, 0 frames \(0 dropped\) in \S+; check the strap's contact, pairing "
                        r"and protocol", done.stderr.strip().splitlines()[-1])
    assert "complete:" not in done.stderr


def test_captures_registering_together_lose_no_row(tmp_path: Path) -> None:
    """Eight threads register eight participants in one registry at once: every row is kept."""
    import threading

    from effortface.capture_tool.participants import register
    from effortface.core.session.folder import Participant

    path = tmp_path / REGISTRY_TSV
    people = [Participant(f"P{i:02d}", "male", 30, 1.8, 80, 5) for i in range(8)]
    threads = [threading.Thread(target=register, args=(path, p)) for p in people]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert sorted(read_registry(path)) == [p.code for p in people]
    assert [p.name for p in tmp_path.iterdir()] == [REGISTRY_TSV]  # the lock is gone


OVERLAP = "start_s,end_s,exercise\n0,30,rest\n20,60,squats\n"
BAD = {
    "missing demographics": ([], None,
                             r"participant P01: expected --age, --height, --training-level \(or a row for P01 in "
                             r"{lab}/participants.tsv\), found none", ["--sex", "male", "--mass", "70"]),
    "overlapping phases": (["--plan", "{plan}"], OVERLAP,
                           r"--plan {plan}: line 3: expected phases that do not overlap, found squats starting at "
                           r"20 s before rest \(line 2\) ends at 30 s", list(BODY)),
    "unknown exercise": (["--plan", "{plan}"], "start_s,end_s,exercise\n0,30,zumba\n",
                         r"--plan {plan}: line 2: exercise 'zumba': expected an id of the catalog \S+"
                         r"exercise_catalog.csv \(rest, ", list(BODY)),
    "negative speed": (["--plan", "{plan}"], "start_s,end_s,exercise,speed_m_s\n0,30,treadmill,-1\n",
                       r"--plan {plan}: line 2: column speed_m_s: expected a number >= 0, found '-1'", list(BODY)),
    "negative load": (["--plan", "{plan}"], "start_s,end_s,exercise,back_kg\n0,30,squats,-5\n",
                      r"--plan {plan}: line 2: column back_kg: expected a number >= 0, found '-5'", list(BODY)),
    "end before start": (["--plan", "{plan}"], "start_s,end_s,exercise\n30,10,rest\n",
                         r"--plan {plan}: line 2: expected 0 <= start_s < end_s, found start_s '30', end_s '10'",
                         list(BODY)),
}


@pytest.mark.parametrize("case", BAD)
def test_bad_capture_input_exit_2_one_line_nothing_written(tmp_path: Path, case: str) -> None:
    extra, plan_text, message, body = BAD[case]
    plan = _plan(tmp_path, plan_text) if plan_text else tmp_path / "none.csv"
    fill = {"plan": re.escape(str(plan)), "lab": re.escape(str(tmp_path / "lab"))}
    done = _capture(tmp_path, "--participant", "P01", *body, *[a.format(plan=plan) for a in extra])
    assert done.returncode == 2, done.stderr
    (line,) = done.stderr.strip().splitlines()
    assert re.fullmatch("effortface capture: error: " + message.format(**fill) + ".*", line), line
    assert not (tmp_path / "lab").exists()


REGISTRY_HEADER = "participant_id\tsex\tage\theight_m\tmass_kg\ttraining_level\thr_rest_bpm\thr_max_bpm\n"


@pytest.mark.parametrize(("rows", "options", "message"), [
    ("P01\tfemale\t30\t1.68\t60\t4\tn/a\tn/a\nP01\tfemale\t30\t1.68\t64\t4\tn/a\tn/a\n", [],
     r"{registry}: line 3: participant P01: expected one row per participant \(or identical rows\), found "
     r"mass_kg 64 here and 60 on line 2"),
    ("P01\tfemale\t30\t1.68\t60\t4\tn/a\tn/a\n", ["--mass", "65"],
     r"participant P01: expected the lab's record \(mass_kg 60 in {registry}\), found mass_kg 65; pass "
     r"--update-participant to change the record \(earlier sessions keep theirs\)"),
    ("P01\tfemale\tthirty\t1.68\t60\t4\tn/a\tn/a\n", [],
     r"{registry}: line 2: column age: expected a number or n/a, found 'thirty'"),
], ids=["conflicting rows", "option against the registry", "not a number"])
def test_bad_registry_exit_2_one_line_nothing_written(tmp_path: Path, rows: str, options: list[str],
                                                      message: str) -> None:
    lab = tmp_path / "lab"
    lab.mkdir()
    registry = lab / REGISTRY_TSV
    registry.write_text(REGISTRY_HEADER + rows, encoding="utf-8")
    done = _capture(tmp_path, "--participant", "P01", *options)
    assert done.returncode == 2, done.stderr
    (line,) = done.stderr.strip().splitlines()
    assert re.fullmatch("effortface capture: error: " + message.format(registry=re.escape(str(registry))), line), line
    assert sorted(p.name for p in lab.iterdir()) == [REGISTRY_TSV]
    assert registry.read_text() == REGISTRY_HEADER + rows
