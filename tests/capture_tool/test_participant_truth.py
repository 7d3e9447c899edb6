"""One truth per participant (issue 25 item 1): the lab's record of a code, on a copy of sample_sessions/.

The sample lab has no ``participants.tsv`` of its own here (the copy drops one if the generator wrote
it), so the registry comes from its sessions; a code whose options differ from the record is refused
in one line, exit 2, nothing written; a code alone records the lab's record (a real HxM capture
replayed through a pseudo-terminal); ``--update-participant`` changes the record, the old one dated.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from effortface.capture_tool.participants import (HISTORY_TSV, REGISTRY_TSV, ParticipantConflict, lab_registry,
                                                  read_history, read_registry, resolve_participant,
                                                  save_participant)
from effortface.core.session.folder import Participant, read_session

from .capture_helpers import effortface, hxm_chunks, start_replay, write_serlog

ROOT = Path(__file__).resolve().parents[2]
#: the lab's P01 in sample_sessions/ (its session.json files)
LAB_P01 = Participant("P01", "female", 23, 1.66, 58.0, 2.5)
WRONG_P01 = ("--sex", "male", "--age", "45", "--training-level", "8")


def copy_sample_lab(dest: Path, with_registry: bool = False) -> Path:
    """A copy of sample_sessions/ (videos left out: the registry reads session.json only)."""
    ignore = ["video.avi", "generate.py"] + ([] if with_registry else [REGISTRY_TSV, HISTORY_TSV])
    shutil.copytree(ROOT / "sample_sessions", dest, ignore=shutil.ignore_patterns(*ignore))
    return dest


def _listing(lab: Path) -> dict[str, str]:
    return {str(p.relative_to(lab)): p.read_text(errors="replace") for p in sorted(lab.rglob("*.json"))
            + sorted(lab.glob("*.tsv"))}


def test_lab_registry_comes_from_the_sessions_when_there_is_no_tsv(tmp_path: Path) -> None:
    lab = copy_sample_lab(tmp_path / "lab")
    people = lab_registry(lab)
    assert sorted(people) == ["P01", "P02", "P03", "P04", "P05", "P06"]
    assert people["P01"] == LAB_P01
    assert lab_registry(tmp_path / "nowhere") == {}


def test_the_latest_session_gives_the_record(tmp_path: Path) -> None:
    lab = copy_sample_lab(tmp_path / "lab")
    newest = lab / "P01_20260119-140000_strength" / "session.json"
    data = json.loads(newest.read_text())
    data["participant"]["mass_kg"] = 59.5
    newest.write_text(json.dumps(data))
    assert lab_registry(lab)["P01"].mass_kg == 59.5


def test_a_conflict_names_every_differing_field_with_both_values(tmp_path: Path) -> None:
    lab = copy_sample_lab(tmp_path / "lab")
    options = {"sex": "male", "age": 45, "height_m": 1.66, "mass_kg": None, "training_level": 8}
    with pytest.raises(ParticipantConflict) as caught:
        resolve_participant("P01", options, lab / REGISTRY_TSV)
    assert caught.value.differences == [("sex", "female", "male"), ("age", 23, 45), ("training_level", 2.5, 8)]
    assert str(caught.value) == (
        f"participant P01: expected the lab's record (sex female, age 23, training_level 2.5 in "
        f"{lab / 'P01_20260119-140000_strength' / 'session.json'}), found sex male, age 45, training_level 8; "
        f"pass --update-participant to change the record (earlier sessions keep theirs)")
    person, save = resolve_participant("P01", dict.fromkeys(options), lab / REGISTRY_TSV)
    assert person == LAB_P01 and not save  # a code alone: the record, nothing to write


def test_saving_a_changed_record_keeps_the_old_one_dated(tmp_path: Path) -> None:
    import datetime as dt

    lab = copy_sample_lab(tmp_path / "lab")
    new = Participant("P01", "female", 24, 1.66, 58.0, 3.0)
    save_participant(lab / REGISTRY_TSV, new, dt.datetime(2026, 3, 1, 9, 0, tzinfo=dt.timezone.utc))
    people = read_registry(lab / REGISTRY_TSV)
    assert sorted(people) == ["P01", "P02", "P03", "P04", "P05", "P06"]  # the lab's others kept
    assert people["P01"] == new
    assert read_history(lab) == [(LAB_P01, "2026-03-01T09:00:00Z")]
    assert json.loads((lab / "P01_20260112-093000_cardio" / "session.json").read_text())["participant"]["age"] == 23


def _capture(lab: Path, port: str, *args: str, duration: str = "1") -> subprocess.CompletedProcess:
    return subprocess.run(effortface("capture", "--port", port, "--protocol", "hxm", "--no-video",
                                     "--duration", duration, "--out", lab, *args),
                          capture_output=True, text=True, timeout=60)


def test_cli_refuses_p01_with_other_demographics_in_one_line_exit_2_nothing_written(tmp_path: Path) -> None:
    lab = copy_sample_lab(tmp_path / "lab")
    before = _listing(lab)
    done = _capture(lab, "loop://", "--participant", "P01", *WRONG_P01)
    assert done.returncode == 2, done.stderr
    (line,) = done.stderr.strip().splitlines()
    source = re.escape(str(lab / "P01_20260119-140000_strength" / "session.json"))
    assert re.fullmatch(r"effortface capture: error: participant P01: expected the lab's record \(sex female, age "
                        rf"23, training_level 2\.5 in {source}\), found sex male, age 45, training_level 8; pass "
                        r"--update-participant to change the record \(earlier sessions keep theirs\)", line), line
    assert done.stdout == ""
    assert _listing(lab) == before  # no session.json, no participants.tsv written
    assert sorted(p.name for p in lab.iterdir() if p.name.startswith("P01_")) == [
        "P01_20260112-093000_cardio", "P01_20260119-140000_strength"]


def test_cli_code_alone_records_the_labs_p01_from_a_real_strap(tmp_path: Path, shared_data: Path) -> None:
    lab = copy_sample_lab(tmp_path / "lab")
    replay, pty = start_replay(write_serlog(tmp_path / "strap.serlog", hxm_chunks(shared_data, 0, 20)),
                               "--speed", "10")
    done = _capture(lab, pty, "--participant", "P01", duration="2")
    replay.terminate()
    replay.wait(10)
    assert done.returncode == 0, done.stderr
    session = read_session(Path(done.stdout.splitlines()[0]))
    assert session.participant == LAB_P01 and len(session.heart_rate) > 0
    assert not (lab / REGISTRY_TSV).exists()  # the record was used, not rewritten


def test_cli_update_participant_changes_the_record_and_keeps_history(tmp_path: Path) -> None:
    lab = copy_sample_lab(tmp_path / "lab")
    done = _capture(lab, "loop://", "--participant", "P01", "--age", "24", "--update-participant")
    assert done.returncode == 1, done.stderr  # loop:// sends no heart rate; the session is kept
    session = Path(done.stdout.splitlines()[0])
    assert read_session(session).participant == Participant("P01", "female", 24, 1.66, 58.0, 2.5)
    assert read_registry(lab / REGISTRY_TSV)["P01"].age == 24
    ((old, when),) = read_history(lab)
    assert old == LAB_P01 and re.fullmatch(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\dZ", when)
    again = _capture(lab, "loop://", "--participant", "P01", "--age", "23")  # the old value is now refused
    assert again.returncode == 2 and "expected the lab's record (age 24 in" in again.stderr


def test_a_registry_without_the_sessions_codes_still_knows_them(tmp_path: Path) -> None:
    """A lab whose participants.tsv was started by an older release with only a new participant (the
    issue's corrupted lab): its sessions' codes stay known, and refused when contradicted."""
    lab = copy_sample_lab(tmp_path / "lab")
    save_participant(lab / REGISTRY_TSV, Participant("P07", "male", 30, 1.8, 80, 5))
    assert sorted(read_registry(lab / REGISTRY_TSV)) == ["P01", "P02", "P03", "P04", "P05", "P06", "P07"]
    (lab / REGISTRY_TSV).write_text("participant_id\tsex\tage\theight_m\tmass_kg\ttraining_level\thr_rest_bpm\t"
                                    "hr_max_bpm\nP07\tmale\t30\t1.8\t80\t5\tn/a\tn/a\n")
    people = lab_registry(lab)
    assert people["P01"] == LAB_P01 and people["P07"].mass_kg == 80
    with pytest.raises(ParticipantConflict, match="participant P01: expected the lab's record"):
        resolve_participant("P01", {"sex": "male"}, lab / REGISTRY_TSV)


def test_captures_saving_together_lose_no_row(tmp_path: Path) -> None:
    """Eight threads save eight new participants in a copy of the sample lab at once (the registry
    is then seeded from its sessions): every row is kept, the lock is gone."""
    import threading

    lab = copy_sample_lab(tmp_path / "lab")
    people = [Participant(f"P{i:02d}", "male", 30, 1.8, 80, 5) for i in range(10, 18)]
    threads = [threading.Thread(target=save_participant, args=(lab / REGISTRY_TSV, p)) for p in people]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert sorted(read_registry(lab / REGISTRY_TSV)) == [f"P0{i}" for i in range(1, 7)] + [p.code for p in people]
    assert not list(lab.glob(".participants.tsv.lock"))
