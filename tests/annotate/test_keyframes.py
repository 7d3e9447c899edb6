"""Key-frame tracks (hold / linear / smooth, edit operations) and the annotations file format."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest

from effortface.core.blendshapes import DEFAULT_SET
from effortface.annotate.keyframes import (
    AnnotationFormatError,
    Keyframe,
    KeyframeTrack,
    origin_seconds,
    RaterAnnotations,
    read_annotations,
)
from effortface.core.errors import UserError


def _track(interp: str) -> KeyframeTrack:
    return KeyframeTrack([Keyframe(10, 0.2, interp), Keyframe(20, 0.8, interp), Keyframe(30, 0.4, interp)])


def test_hold_is_a_step_until_the_next_key() -> None:
    w = _track("hold").evaluate([0, 10, 15, 19.9, 20, 25, 30, 99])
    np.testing.assert_allclose(w, [0.2, 0.2, 0.2, 0.2, 0.8, 0.8, 0.4, 0.4])


def test_linear_is_a_straight_line_between_keys() -> None:
    w = _track("linear").evaluate([5, 10, 12.5, 15, 20, 25, 30, 40])
    np.testing.assert_allclose(w, [0.2, 0.2, 0.35, 0.5, 0.8, 0.6, 0.4, 0.4])


def test_smooth_is_smoothstep_monotone_with_flat_ends() -> None:
    x = np.linspace(10, 20, 101)
    w = _track("smooth").evaluate(x)
    u = (x - 10) / 10
    np.testing.assert_allclose(w, 0.2 + 0.6 * (3 * u**2 - 2 * u**3))
    assert np.all(np.diff(w) >= 0) and w.min() >= 0.2 and w.max() <= 0.8  # never overshoots
    assert w[1] - w[0] < (w[51] - w[50]) / 10  # flat at the key, steep in the middle


def test_interpolation_is_per_key_segment() -> None:
    track = KeyframeTrack([Keyframe(0, 0.0, "hold"), Keyframe(10, 1.0, "linear"), Keyframe(20, 0.0)])
    np.testing.assert_allclose(track.evaluate([5, 10, 15]), [0.0, 1.0, 0.5])


def test_vectorised_evaluation_equals_per_frame_evaluation() -> None:
    rng = np.random.default_rng(1)
    track = KeyframeTrack()
    for f in rng.choice(500, 40, replace=False):
        track.add(int(f), float(rng.random()), ("hold", "linear", "smooth")[int(f) % 3])
    x = np.arange(-5, 510)
    np.testing.assert_array_equal(track.evaluate(x), [track.evaluate(v)[()] for v in x])
    assert track.evaluate(x.reshape(5, -1)).shape == (5, 103)


def test_empty_track_is_not_annotated_and_single_key_is_constant() -> None:
    assert np.isnan(KeyframeTrack().evaluate([0, 5])).all()
    np.testing.assert_allclose(KeyframeTrack([Keyframe(7, 0.3)]).evaluate([0, 7, 100]), 0.3)


def test_add_replaces_move_and_delete() -> None:
    track = _track("linear")
    track.add(20, 0.5, "smooth")
    assert len(track) == 3 and track.get(20) == Keyframe(20, 0.5, "smooth")
    moved = track.move(20, 22, weight=0.6)
    assert moved == Keyframe(22, 0.6, "smooth") and track.get(20) is None
    assert [k.frame for k in track.keys] == [10, 22, 30]
    with pytest.raises(ValueError, match="already keyed"):
        track.move(22, 30)
    assert track.delete(10).weight == 0.2 and len(track) == 2
    with pytest.raises(KeyError, match="no key-frame on frame 10"):
        track.delete(10)
    with pytest.raises(KeyError):
        track.move(99, 100)


@pytest.mark.parametrize("match, key", [
    (r"frame: expected an integer >= 0, found -1", dict(frame=-1, weight=0.5)),
    (r"frame: expected an integer >= 0, found 1.5", dict(frame=1.5, weight=0.5)),
    (r"weight: expected a number in \[0, 1\], found 1.2", dict(frame=1, weight=1.2)),
    (r"weight: expected a number in \[0, 1\], found 'x'", dict(frame=1, weight="x")),
    (r"interp: expected one of hold, linear, smooth, found 'cubic'", dict(frame=1, weight=0.1, interp="cubic")),
])
def test_bad_keys_are_refused(match: str, key: dict) -> None:
    with pytest.raises(UserError, match=match):
        Keyframe(**key)


def _annotations() -> RaterAnnotations:
    ann = RaterAnnotations("R1", "P01_20260112-093000_cardio")
    ann.tracks["mouth_open"].add(0, 0.0, "hold")
    ann.tracks["mouth_open"].add(40, 0.55, "smooth")
    ann.tracks["eye_squint"].add(12, 0.25)
    return ann


def test_save_read_round_trip(tmp_path) -> None:
    path = _annotations().save(tmp_path / "annotations" / "R1.json")
    back = read_annotations(path)
    assert back == _annotations()
    assert back.blendshapes == DEFAULT_SET and len(back.tracks["brow_lower"]) == 0
    w = back.weights([0, 20, 40])
    assert w.shape == (3, 4) and np.isnan(w[:, 0]).all()
    np.testing.assert_allclose(w[:, 1], [0.0, 0.0, 0.55])
    doc = json.loads(path.read_text())
    assert doc["schema_version"] == 2 and list(doc["tracks"]) == list(DEFAULT_SET.names)


def test_copy_is_independent() -> None:
    ann = _annotations()
    snapshot = ann.copy()
    ann.tracks["mouth_open"].delete(40)
    assert len(snapshot.tracks["mouth_open"]) == 2 and snapshot != ann


def test_save_refuses_to_overwrite_unless_told(tmp_path) -> None:
    path = _annotations().save(tmp_path / "R1.json")
    ann = _annotations()
    ann.tracks["brow_lower"].add(5, 0.9)
    with pytest.raises(FileExistsError, match="refusing to overwrite"):
        ann.save(path)
    assert len(read_annotations(path).tracks["brow_lower"]) == 0
    ann.save(path, overwrite=True)
    assert read_annotations(path).tracks["brow_lower"].get(5).weight == 0.9


def test_a_failed_save_keeps_the_previous_file_and_leaves_no_temp(tmp_path, monkeypatch) -> None:
    path = _annotations().save(tmp_path / "R1.json")
    before = path.read_bytes()

    def crash(src, dst):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", crash)
    with pytest.raises(OSError, match="disk full"):
        _annotations().save(path, overwrite=True)
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["R1.json"]


def _doc(**changes) -> dict:
    doc = _annotations().to_dict()
    doc.update(changes)
    return doc


@pytest.mark.parametrize("match, content", [
    (r"expected a JSON annotation file", "{not json"),
    (r"expected a JSON object, found list", json.dumps([1, 2])),
    (r"schema_version: expected 1 or 2, found 3", json.dumps(_doc(schema_version=3))),
    (r"tracks.mouth_open\[0\]: key-frame origin: expected one of typed, machine, edited, found 'robot'",
     json.dumps(_doc(tracks={"mouth_open": [{"frame": 3, "weight": 0.1, "origin": "robot"}]}))),
    (r"tracks.mouth_open\[0\]: key-frame accepted_by: expected the accepting rater's code",
     json.dumps(_doc(tracks={"mouth_open": [{"frame": 3, "weight": 0.1, "origin": "machine"}]}))),
    (r"rater: expected a non-empty string, found ''", json.dumps(_doc(rater=""))),
    (r"blendshapes: expected unique, non-empty names", json.dumps(_doc(blendshapes=[]))),
    (r"tracks: expected an object", json.dumps(_doc(tracks=[]))),
    (r"blendshape: expected one of .* found 'smile'", json.dumps(_doc(tracks={"smile": []}))),
    (r"tracks.mouth_open\[0\]: key-frame weight: expected a number in \[0, 1\], found -0.1",
     json.dumps(_doc(tracks={"mouth_open": [{"frame": 3, "weight": -0.1}]}))),
    (r"tracks.mouth_open\[1\]: expected one key per frame, found frame 3 twice",
     json.dumps(_doc(tracks={"mouth_open": [{"frame": 3, "weight": 0.1}, {"frame": 3, "weight": 0.2}]}))),
    (r"tracks.eye_squint\[0\]: expected \{frame, weight, interp\}",
     json.dumps(_doc(tracks={"eye_squint": [{"weight": 0.2}]}))),
])
def test_bad_files_raise_naming_the_file(tmp_path, match: str, content: str) -> None:
    path = tmp_path / "R9.json"
    path.write_text(content)
    with pytest.raises(AnnotationFormatError, match=match) as err:
        read_annotations(path)
    assert str(path) in str(err.value) and "\n" not in str(err.value)


def test_missing_file_names_it(tmp_path) -> None:
    with pytest.raises(AnnotationFormatError, match="R7.json"):
        read_annotations(tmp_path / "R7.json")


def test_a_version_1_file_loads_every_key_as_typed(tmp_path) -> None:
    doc = _annotations().to_dict()
    doc["schema_version"] = 1
    for keys in doc["tracks"].values():
        for key in keys:
            key.pop("origin")
            key["origin"] = "machine"  # a version 1 file knows no origins: ignored, typed
    path = tmp_path / "R1.json"
    path.write_text(json.dumps(doc))
    back = read_annotations(path)
    keys = [k for t in back.tracks.values() for k in t.keys]
    assert keys and all(k.origin == "typed" and k.human for k in keys)
    assert back == _annotations()


def test_origins_round_trip_and_an_edit_makes_a_machine_key_the_raters(tmp_path) -> None:
    track = KeyframeTrack([Keyframe(0, 0.1), Keyframe(30, 0.5, origin="machine", accepted_by="R2"),
                           Keyframe(60, 0.2, origin="machine", accepted_by="R2")])
    ann = RaterAnnotations("R2", "S1", DEFAULT_SET, {"mouth_open": track})
    doc = json.loads(ann.save(tmp_path / "R2.json").read_text())
    assert doc["tracks"]["mouth_open"][1] == {"frame": 30, "weight": 0.5, "interp": "linear",
                                              "origin": "machine", "accepted_by": "R2"}
    assert doc["tracks"]["mouth_open"][0]["origin"] == "typed"
    back = read_annotations(tmp_path / "R2.json").tracks["mouth_open"]
    assert [k.origin for k in back.keys] == ["typed", "machine", "machine"]
    # the label at each frame is the nearest key's: the machine's from frame 16 on
    assert back.origins([0, 15, 16, 45, 60]).tolist() == ["typed", "typed", "machine", "machine", "machine"]
    assert np.isnan(back.evaluate_human([16, 60])).all() and back.evaluate_human([0])[0] == 0.1
    moved = back.move(60, 62)
    assert (moved.origin, moved.accepted_by) == ("edited", None) and moved.human
    assert back.get(30).origin == "machine"  # the others stay the machine's
    times = np.arange(63) * 1.0  # one frame per second
    assert origin_seconds(back, times) == {"typed": 16, "machine": 31, "edited": 16}
