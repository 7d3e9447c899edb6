"""The Qt-free annotation session model: protocol order, passes, keys, undo/redo, copy/paste, autosave,
never overwriting another file; the blind round; the exports. No Qt, no sleeps."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from effortface.annotate.export import write_keyframes_json, write_weights_csv
from effortface.annotate.keyframes import read_annotations
from effortface.annotate.reliability import read_ratings
from effortface.annotate.annotate_session import AnnotateSession, BlindRound, annotation_path
from effortface.core.errors import UserError

ROOT = Path(__file__).resolve().parents[2]
SAMPLES = ROOT / "sample_sessions"
SESSION = "P03_20260113-094400_cardio"


@pytest.fixture
def session(tmp_path: Path) -> Path:
    dst = tmp_path / SESSION
    dst.mkdir()
    for f in ("session.json", "heart_rate.csv", "events.csv", "video_frames.csv"):
        shutil.copy(SAMPLES / SESSION / f, dst)
    shutil.copytree(SAMPLES / SESSION / "annotations", dst / "annotations")
    return dst


def test_protocol_order_and_passes(session: Path) -> None:
    m = AnnotateSession(session, "R9")
    seen: list[tuple[str, object]] = []
    m.blendshape_changed.connect(lambda name: seen.append(("blendshape_changed", name)))
    m.passes_changed.connect(lambda name: seen.append(("passes_changed", name)))
    assert m.blendshape == "mouth_stretch" and m.next_blendshape == "mouth_open"
    m.set_frame(m.n_frames - 1)
    assert not m.passes_done  # reaching the end without a key is no pass
    m.set_key(0.2, frame=0)
    m.set_frame(10)
    m.set_frame(m.n_frames - 1)
    assert m.passes_done == {"mouth_stretch"} and ("passes_changed", "mouth_stretch") in seen
    assert m.start_next_pass() == "mouth_open" and m.frame == 0
    m.set_blendshape("brow_lower")
    assert m.next_blendshape is None and m.start_next_pass() is None
    with pytest.raises(UserError, match="blendshape: expected one of"):
        m.set_blendshape("smile")


def test_edits_autosave_undo_and_redo(session: Path) -> None:
    m = AnnotateSession(session, "R9")
    path = annotation_path(session, "R9")
    assert not path.exists()
    m.set_key(0.3, frame=5)
    m.set_key(0.8, frame=50, interp="smooth")
    m.move_key(50, 60, 0.9)
    m.set_interp("hold", frame=5)
    assert read_annotations(path).to_dict() == m.annotations.to_dict()
    assert [(k.frame, k.weight, k.interp) for k in m.track.keys] == [(5, 0.3, "hold"), (60, 0.9, "smooth")]
    assert m.undo() and m.undo()
    assert [(k.frame, k.weight) for k in m.track.keys] == [(5, 0.3), (50, 0.8)]
    assert read_annotations(path).to_dict() == m.annotations.to_dict()
    assert m.redo() and m.track.get(60).weight == 0.9
    m.delete_key(5)
    assert not m.can_redo  # a new edit clears the redo list
    assert m.delete_key(5) is None
    with pytest.raises(UserError, match="weight: expected a number in \\[0, 1\\]"):
        m.set_key(1.5)
    with pytest.raises(ValueError, match="frame already keyed"):
        m.set_key(0.1, frame=70)
        m.move_key(70, 60)
    assert m.track.get(70) is not None and m.track.get(60).weight == 0.9  # the failed move changed nothing


def test_copy_paste_is_one_undo_step(session: Path) -> None:
    m = AnnotateSession(session, "R9", autosave=False)
    for f, w in ((10, 0.1), (12, 0.5), (15, 0.2)):
        m.set_key(w, frame=f)
    assert m.copy(10, 15) == 3
    assert m.paste(100) == 3
    assert [(k.frame, k.weight) for k in m.track.keys][3:] == [(100, 0.1), (102, 0.5), (105, 0.2)]
    m.undo()
    assert len(m.track) == 3


def test_weights_follow_the_interpolation(session: Path) -> None:
    m = AnnotateSession(session, "R9", autosave=False)
    assert np.isnan(m.weight())
    m.set_key(0.0, frame=0, interp="linear")
    m.set_key(1.0, frame=10)
    assert m.weight(5) == pytest.approx(0.5)
    m.set_interp("hold", frame=0)
    assert m.weight(5) == 0.0
    assert np.isnan(m.weights(5)["mouth_open"])


def test_a_rater_sees_only_their_own_file_and_another_file_is_never_overwritten(session: Path) -> None:
    r1 = AnnotateSession(session, "R1")
    assert r1.annotations == read_annotations(session / "annotations" / "R1.json")
    new = AnnotateSession(session, "R9")
    shutil.copy(session / "annotations" / "R1.json", session / "annotations" / "R9.json")  # appears meanwhile
    with pytest.raises(FileExistsError, match="refusing to overwrite"):
        new.set_key(0.5)
    assert len(new.track) == 0  # the edit was rolled back


@pytest.mark.parametrize("rater", ["", "a b", "../R1", "x" * 40])
def test_bad_rater_codes(session: Path, rater: str) -> None:
    with pytest.raises(UserError, match="rater: expected a code"):
        AnnotateSession(session, rater)


def test_blind_round_saves_only_this_raters_ratings(tmp_path: Path) -> None:
    shutil.copytree(SAMPLES / "reliability", tmp_path / "reliability")
    r1 = BlindRound(tmp_path, "R1")
    assert r1.complete
    with pytest.raises(UserError, match="already rated by R1"):
        r1.set_rating("pose01", "mouth_open", 0.5)
    r4 = BlindRound(tmp_path, "R4")
    assert not r4.complete and not r4.ratings
    r4.set_rating("pose02", "eye_squint", 0.35)
    assert [(r.pose_id, r.rater, r.weight) for r in read_ratings(tmp_path / "reliability" / "ratings_R4.csv")] \
        == [("pose02", "R4", 0.35)]
    assert BlindRound(tmp_path, "R4").rating("pose02", "eye_squint") == 0.35
    with pytest.raises(UserError, match="pose: expected one of the pose set"):
        r4.set_rating("pose99", "eye_squint", 0.1)
    with pytest.raises(UserError, match="poses.csv: expected the reliability pose set"):
        BlindRound(tmp_path / "nowhere", "R4")


def test_exports_refuse_to_overwrite(session: Path, tmp_path: Path) -> None:
    m = AnnotateSession(session, "R2")
    out = write_weights_csv(m.annotations, m.times, tmp_path / "w.csv")
    lines = out.read_text().splitlines()
    assert len(lines) == m.n_frames + 1 and lines[1].startswith("0,")
    with pytest.raises(FileExistsError):
        write_weights_csv(m.annotations, m.times, out)
    keys = write_keyframes_json(m.annotations, tmp_path / "k.json")
    assert read_annotations(keys) == m.annotations
    with pytest.raises(FileExistsError):
        write_keyframes_json(m.annotations, keys)


def test_a_finished_round_is_locked(tmp_path: Path) -> None:
    """Once every pose is rated the rater has seen the report: no rating may change any more."""
    shutil.copytree(SAMPLES / "reliability", tmp_path / "reliability")
    r4 = BlindRound(tmp_path, "R4")
    for pose in r4.poses:
        for name in r4.blendshapes.names:
            r4.set_rating(pose.pose_id, name, 0.25)
    assert r4.complete
    before = (tmp_path / "reliability" / "ratings_R4.csv").read_bytes()
    with pytest.raises(UserError, match="R4 has finished the blind round and seen the agreement report"):
        r4.set_rating("pose01", "mouth_open", 0.9)
    with pytest.raises(UserError, match="finished the blind round"):
        BlindRound(tmp_path, "R4").set_rating("pose02", "eye_squint", 0.1)  # also after reopening
    assert (tmp_path / "reliability" / "ratings_R4.csv").read_bytes() == before
    assert r4.rating("pose01", "mouth_open") == 0.25


def test_undo_names_the_step_and_goes_to_its_blendshape_and_frame(session: Path) -> None:
    """Issue 16 item 6: after N, Ctrl+Z must not silently revert an off-screen blendshape."""
    m = AnnotateSession(session, "R9")
    said: list[tuple[str, bool]] = []
    history: list[int] = []
    m.status_changed.connect(lambda text, is_error: said.append((text, is_error)))
    m.history_changed.connect(lambda: history.append(len(m.history[0])))
    assert not m.can_undo and m.undo_text == "" and m.undo() is None and said[-1][1]  # "nothing to undo"
    m.set_frame(40)
    m.set_key(0.6)  # mouth_stretch at frame 40
    m.start_next_pass()  # N: now on mouth_open, frame 0
    assert (m.blendshape, m.frame) == ("mouth_open", 0)
    assert m.undo_text == "set mouth_stretch key at frame 40 to 0.60"
    text = m.undo()
    assert text == "undid: set mouth_stretch key at frame 40 to 0.60" and said[-1] == (text, False)
    assert (m.blendshape, m.frame) == ("mouth_stretch", 40) and m.key_at() is None  # shown where it happened
    assert m.redo_text and m.history == ([], ["set mouth_stretch key at frame 40 to 0.60"])
    m.set_blendshape("eye_squint")
    assert m.redo() == "redid: set mouth_stretch key at frame 40 to 0.60"
    assert m.blendshape == "mouth_stretch" and m.key_at(40).weight == 0.6
    assert history == [1, 0, 1]


def test_history_jump_and_multi_key_moves_are_single_steps(session: Path) -> None:
    m = AnnotateSession(session, "R9", autosave=False)
    for f, w in ((10, 0.2), (20, 0.4), (30, 0.6)):
        m.set_key(w, f)
    assert m.shift_keys([10, 20, 30], d_frames=5, d_weight=0.1) == [15, 25, 35]
    assert [(k.frame, k.weight) for k in m.track.keys] == [(15, 0.3), (25, 0.5), (35, 0.7)]
    m.shift_keys([15, 25, 35], scale=2.0)  # about the mean 0.5
    assert [k.weight for k in m.track.keys] == pytest.approx([0.1, 0.5, 0.9])
    with pytest.raises(UserError, match="key in the way"):
        m.shift_keys([15], d_frames=10)  # onto the key at 25
    assert len(m.history[0]) == 5
    assert m.undo_to(2) == 2 and [k.frame for k in m.track.keys] == [10, 20, 30]
    assert m.undo_to(-1) == 1 and [k.frame for k in m.track.keys] == [15, 25, 35]


def test_a_pass_is_saved_in_the_file_and_survives_undo(session: Path) -> None:
    m = AnnotateSession(session, "R9")
    m.set_key(0.3)
    m.set_frame(m.n_frames - 1)
    assert read_annotations(m.path).passes_done == {"mouth_stretch"}
    m.undo()  # the key goes, the finished pass stays recorded
    assert m.passes_done == {"mouth_stretch"}
    m.close()  # one Annotate per session and rater at a time (the rater file's lock)
    assert AnnotateSession(session, "R9").passes_done == {"mouth_stretch"}


def test_blind_round_refuses_unrated_as_a_rating(tmp_path: Path) -> None:
    shutil.copytree(SAMPLES / "reliability", tmp_path / "reliability")
    blind = BlindRound(tmp_path, "R9")
    pose = blind.poses[0].pose_id
    with pytest.raises(UserError, match="unrated is not a rating"):
        blind.set_rating(pose, "mouth_open", None)
    assert blind.rating(pose, "mouth_open") is None and not blind.path.exists()


@pytest.mark.parametrize(("frames", "d_frames", "edge"), [
    ("last3", 1, "last frame"), ("first3", -1, "first frame (0)"), ("last3", 10, "last frame")],
    ids=["last key one right", "first key one left", "ten right"])
def test_a_move_that_cannot_move_every_key_moves_none_and_says_why(session: Path, frames: str, d_frames: int,
                                                                 edge: str) -> None:
    """Issue 25 item 4: keys 0, 30 and the last frame moved right used to become 1, 31, last."""
    m = AnnotateSession(session, "R9", autosave=False)
    last = m.n_frames - 1
    chosen = [last - 63, last - 33, last] if frames == "last3" else [0, 30, 63]
    for f in chosen:
        m.set_key(0.5, f)
    before = [(k.frame, k.weight) for k in m.track.keys]
    n_history = len(m.history[0])
    stuck = str(last) if frames == "last3" else "0"
    expected = re.escape(f"move keys: expected every selected key to move by {d_frames:+d} frames, found key "
                         f"{stuck} within {abs(d_frames)} frame") + r"s? of the " + re.escape(edge) + r".*: nothing moved"
    with pytest.raises(UserError, match=expected):
        m.shift_keys(chosen, d_frames=d_frames)
    assert [(k.frame, k.weight) for k in m.track.keys] == before and len(m.history[0]) == n_history
    # away from the edge every key moves, and the history says so
    back = m.shift_keys(chosen, d_frames=-d_frames)
    assert back == [f - d_frames for f in chosen]
    assert m.history[0][-1].endswith(f"move 3 mouth_stretch keys by {-d_frames:+d} frames")


def test_a_finished_rating_is_corrected_with_the_change_logged(tmp_path: Path) -> None:
    """After the round a typo is corrected with a reason: logged (time UTC, pose, blendshape, old, new,
    reason), the ratings file rewritten, the report's input changed; refused without a reason, before the
    round ends, for the lab's own ratings and for the same value."""
    import datetime

    from effortface.annotate.agreement import gather_ratings
    from effortface.annotate.reliability import read_corrections

    shutil.copytree(SAMPLES / "reliability", tmp_path / "reliability")
    r4 = BlindRound(tmp_path, "R4")
    with pytest.raises(UserError, match="not finished"):
        r4.correct_rating("pose01", "mouth_open", 0.7, "typo")
    for pose in r4.poses:
        for name in r4.blendshapes.names:
            r4.set_rating(pose.pose_id, name, 0.25)
    before = (tmp_path / "reliability" / "ratings_R4.csv").read_bytes()
    with pytest.raises(UserError, match="expected a reason"):
        r4.correct_rating("pose01", "mouth_open", 0.7, "  ")
    with pytest.raises(UserError, match="same"):
        r4.correct_rating("pose01", "mouth_open", 0.25, "typo")
    with pytest.raises(UserError, match=r"weight: expected a number in \[0, 1\]"):
        r4.correct_rating("pose01", "mouth_open", 7.0, "typo")
    assert (tmp_path / "reliability" / "ratings_R4.csv").read_bytes() == before
    assert not r4.corrections_path.exists()
    when = datetime.datetime(2026, 3, 1, 10, 30, tzinfo=datetime.timezone.utc)
    r4.correct_rating("pose01", "mouth_open", 0.7, "typo: 0.25 for 0.7", when_utc=when)
    r4.correct_rating("pose02", "eye_squint", 0.1, "wrong row")
    log = read_corrections(tmp_path / "reliability" / "corrections_R4.csv")
    assert [(c.pose_id, c.blendshape, c.old, c.new, c.reason) for c in log] == [
        ("pose01", "mouth_open", 0.25, 0.7, "typo: 0.25 for 0.7"), ("pose02", "eye_squint", 0.25, 0.1, "wrong row")]
    assert log[0].time_utc == "2026-03-01T10:30:00Z" and re.fullmatch(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\dZ", log[1].time_utc)
    reopened = BlindRound(tmp_path, "R4")
    assert reopened.rating("pose01", "mouth_open") == 0.7 and reopened.complete
    ratings, _ = gather_ratings(tmp_path)
    assert {(r.pose_id, r.blendshape): r.weight for r in ratings if r.rater == "R4"}[("pose01", "mouth_open")] == 0.7
    assert not list((tmp_path / "reliability").glob(".*.tmp"))
    r1 = BlindRound(tmp_path, "R1")  # R1's ratings are in the lab's ratings.csv
    with pytest.raises(UserError, match="the lab's file"):
        r1.correct_rating("pose01", "mouth_open", 0.99 if r1.rating("pose01", "mouth_open") != 0.99 else 0.5, "typo")
