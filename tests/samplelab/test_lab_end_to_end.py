"""A lab recorded end to end by the product: capture -> (rater files) -> work -> train.

Three participants' strap logs (the sample lab's ``serial/*.serlog``) are replayed by
``effortface replay`` through pseudo-terminals into ``effortface capture --plan ... --video
<sample video>``; the first capture of each participant registers its demographics in the lab's
participants.tsv. The raters' key-frame files are copied in (annotation is a person's job), then
``effortface work`` and ``effortface train`` run on the captured sessions. Every other file is made
by the product.
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

from effortface.core.session.folder import read_session
from effortface.synth.exercise_log import read_exercise_log

from tests.capture_tool.capture_helpers import effortface, start_replay

SAMPLES = Path(__file__).resolve().parents[2] / "sample_sessions"
#: three participants of distinct training levels, three strap protocols' worth of bytes
SOURCES = ("P01_20260112-093000_cardio", "P02_20260112-113700_strength", "P03_20260120-142200_strength")
REPLAY_SPEED = 12.0  # the 10-12-minute strap logs in about 1 minute of capture


def _plan(source: Path, out: Path) -> Path:
    """The lab manager's plan: the sample session's own protocol, at the replay's pace.

    Read from its exercise log (phases, speeds, back loads), times divided by the replay speed so
    that the work logged lines up with the heart rate the strap log replays.
    """
    log = read_exercise_log(source)
    rows = ["start_s,end_s,exercise,speed_m_s,back_kg"]
    for phase in log.phases:
        gait = phase.exercise.startswith("treadmill")
        *_, (_, _, state) = log.states(phase, ("treadmill",) if gait else ())  # as set during the phase
        exercise = "treadmill" if gait else phase.exercise
        speed = "" if state.speed_m_s is None else f"{state.speed_m_s:g}"
        rows.append(f"{phase.start_s / REPLAY_SPEED:.2f},{phase.end_s / REPLAY_SPEED:.2f},{exercise},{speed},"
                    f"{state.load_kg('back_kg'):g}")
    out.write_text("\n".join(rows) + "\n", encoding="utf-8")
    return out


def _body(source: Path) -> list[str]:
    p = json.loads((source / "session.json").read_text())["participant"]
    return ["--participant", p["code"], "--sex", p["sex"], "--age", str(p["age"]), "--height", str(p["height_m"]),
            "--mass", str(p["mass_kg"]), "--training-level", str(p["training_level"])]


@pytest.mark.slow
def _key_like(source: Path, session: Path) -> None:
    """Each rater's key-frames of ``source``, saved for ``session`` through the product's own writer.

    An annotation file names its session (a file copied from another session is refused by
    train: issue 17), so the keys are re-saved under the new session's id, as the rater would have
    keyed them in Annotate.
    """
    import dataclasses

    from effortface.annotate.keyframes import read_annotations

    (session / "annotations").mkdir()
    for path in sorted((source / "annotations").glob("*.json")):
        keys = read_annotations(path)
        dataclasses.replace(keys, session_id=session.name).save(session / "annotations" / path.name)


def test_a_lab_recorded_by_the_product_trains(tmp_path: Path) -> None:
    lab = tmp_path / "lab"
    runs = []
    for name in SOURCES:
        source = SAMPLES / name
        serlog = read_session(source).serlog_paths()[0]
        protocol = read_session(source).devices["heart_rate"]["protocol"]
        plan = _plan(source, tmp_path / f"{name}.plan.csv")
        replay, pty = start_replay(serlog, "--speed", str(REPLAY_SPEED))
        cap = subprocess.Popen(effortface("capture", "--port", pty, "--protocol", protocol, *_body(source),
                                          "--video", source / "video.avi", "--plan", plan, "--out", lab),
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        runs.append((source, replay, cap))
    sessions = []
    for source, replay, cap in runs:
        out, err = cap.communicate(timeout=120)
        replay.terminate()
        replay.wait(10)
        assert cap.returncode == 0, err
        session = Path(out.splitlines()[0])
        assert read_session(session).info.complete and f"phase 1/" in out
        _key_like(source, session)  # the raters key the new session as they keyed its source
        sessions.append(session)
    registry = (lab / "participants.tsv").read_text().splitlines()
    assert registry[0].startswith("participant_id\t")  # three captures started together: none lost
    assert sorted(row.split("\t")[0] for row in registry[1:]) == ["P01", "P02", "P03"]
    work = subprocess.run(effortface("work", lab), capture_output=True, text=True, timeout=120)
    assert work.returncode == 0, work.stderr
    assert all((s / "work.csv").is_file() for s in sessions)
    model = tmp_path / "model"
    train = subprocess.run(effortface("train", lab, "--out", model, "--max-rows", "40"),
                           capture_output=True, text=True, timeout=600)
    assert train.returncode == 0, train.stderr[-2000:]
    assert (model / "model.json").is_file() and (model / "face.onnx").is_file()
