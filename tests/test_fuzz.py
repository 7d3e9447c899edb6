"""Fuzzing (issue 17): the decoders and every session-file reader, with hypothesis.

Brief on every change (fixed seed: ``derandomize=True``, 150 examples per property, about 15 s, the CI job
``.ci/fuzz``), long in ``benchmarks/fuzz_long.py`` (``EFFORTFACE_FUZZ_EXAMPLES`` examples per
property, random seeds). The promises checked:

- a decoder fed any bytes in any chunking never raises, returns the same samples whatever the
  chunking, and keeps its counters consistent (samples counted = samples returned, invalid ones
  too, never more bytes dropped than fed, an empty buffer after ``finish``);
- a reader given a mutated file (bytes flipped, inserted, deleted, truncated, or a JSON field given
  a value of any type) returns or raises a :class:`UserError` with a one-line message, never
  another exception and never a hang (each call runs under an alarm).
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from effortface.annotate.agreement import frames_by_session
from effortface.annotate.keyframes import read_annotations
from effortface.annotate.machine.track import read_machine_track
from effortface.annotate.reliability import read_poses, read_ratings
from effortface.core.blendshapes import DEFAULT_SET
from effortface.core.session.hr_csv import read_hr_csv
from effortface.capture_tool.protocols import PROTOCOLS, get_decoder
from effortface.capture_tool.protocols.encode import encode_line
from effortface.capture_tool.serlog import DATA, read_serlog
from effortface.core.session.folder import read_events, read_session_info, read_video_frames
from effortface.core.errors import UserError
from effortface.synth.bundle import read_bundle, write_bundle
from effortface.synth.work import _segment_mapping, read_motion_index, read_work_csv, write_work
from effortface.synth.motion import read_motion
from effortface.annotate.machine.landmarker import DEFAULT_MODEL, FaceLandmarker
from effortface.annotate.machine.landmarker import read_bundle as read_landmarker_bundle

pytestmark = pytest.mark.fuzz

ROOT = Path(__file__).resolve().parents[1]
SESSION = ROOT / "sample_sessions" / "P03_20260113-094400_cardio"
MOTION_JSON = ROOT / "sample_sessions" / "P02_20260112-113700_strength" / "motion" / "motion.json"
SERIAL = ROOT / "tests" / "data" / "serial"
#: examples per property (the long run raises it)
EXAMPLES = int(os.environ.get("EFFORTFACE_FUZZ_EXAMPLES", "150"))
#: seconds one reader call may take before it counts as a hang
HANG_S = 10.0
FUZZ = settings(max_examples=EXAMPLES, deadline=None, database=None,
                derandomize=os.environ.get("EFFORTFACE_FUZZ_RANDOM") != "1",
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])


# ----------------------------------------------------------------------------------- decoders


def _seed_streams() -> dict[str, bytes]:
    """Real bytes of each protocol (recorded streams, the sample session's serial log, encoded lines)."""
    hrmi = b"".join(r.payload for r in read_serlog(SESSION / "serial" / "hrmi.serlog").records if r.kind == DATA)
    return {
        "ant": (SERIAL / "derived" / "njcant_hrm1_ant_broadcast.bin").read_bytes()[:3000],
        "hxm": (SERIAL / "zephyr-bt" / "120-second-bt-stream-hxm.dat").read_bytes()[:3000],
        "hrmi": hrmi[:3000],
        "lines": b"".join(encode_line(hr, rr) for hr, rr in ((60 + i % 90, 600 + 7 * i) for i in range(80))),
        "ble_hrm": _ble_notifications(),
    }


def _ble_notifications() -> bytes:
    """Framed 0x2A37 notifications carrying the real R-R intervals of tests/data/hr (one beat each)."""
    from effortface.capture_tool.protocols.ble_hrm import build_measurement, frame

    lines = (ROOT / "tests" / "data" / "hr" / "polar-h10-sensor-logger_RR.txt").read_text().splitlines()[1:200]
    rr = [float(line.split(";")[1]) for line in lines]
    return b"".join(frame(build_measurement(round(60000 / r), (r,), contact=True, energy_kj=k if k % 7 == 0 else None,
                                            hr16=k % 5 == 0)) for k, r in enumerate(rr))[:3000]


STREAMS = _seed_streams()


@st.composite
def mutated(draw: st.DrawFn, data: bytes) -> bytes:
    """``data`` with a few random edits: flips, inserts, deletions, duplications, truncation, nesting."""
    out = bytearray(data)
    for _ in range(draw(st.integers(0, 6))):
        kind = draw(st.sampled_from(["flip", "insert", "delete", "dup", "truncate", "nest"]))
        at = draw(st.integers(0, max(len(out) - 1, 0)))
        if kind == "flip" and out:
            out[at] ^= 1 << draw(st.integers(0, 7))
        elif kind == "insert":
            out[at:at] = draw(st.binary(min_size=1, max_size=40))
        elif kind == "delete":
            del out[at:at + draw(st.integers(1, 40))]
        elif kind == "dup":
            out[at:at] = out[at:at + draw(st.integers(1, 200))]
        elif kind == "truncate":
            del out[at:]
        elif kind == "nest":  # deep brackets: Python's JSON parser recurses
            depth = draw(st.integers(1, 5000))
            out[at:at] = b"[" * depth + b"]" * depth
    return bytes(out)


def _chunks(data: bytes, cuts: list[int]) -> list[bytes]:
    """``data`` cut at the given offsets (any order, any repeats)."""
    points = sorted({0, len(data), *(c % (len(data) + 1) for c in cuts)})
    return [data[a:b] for a, b in zip(points, points[1:])]


def _decode(protocol: str, chunks: list[bytes]):
    dec = get_decoder(protocol)
    samples = []
    for chunk in chunks:
        samples += dec.feed(chunk, 0.0)
    samples += dec.finish()
    return samples, dec


@pytest.mark.parametrize("protocol", sorted(PROTOCOLS))
@FUZZ
@given(data=st.data())
def test_decoders_take_any_bytes_in_any_chunking(protocol: str, data: st.DataObject) -> None:
    stream = data.draw(st.one_of(mutated(STREAMS[protocol]), st.binary(max_size=600)), label="stream")
    cuts = data.draw(st.lists(st.integers(0, 1 << 16), max_size=40), label="cuts")
    whole, dec = _decode(protocol, [stream])
    chunked, dec_chunked = _decode(protocol, _chunks(stream, cuts))
    assert [(s.hr_bpm, s.rr_ms, s.valid) for s in chunked] == [(s.hr_bpm, s.rr_ms, s.valid) for s in whole]
    for d, samples in ((dec, whole), (dec_chunked, chunked)):
        stats = d.stats
        assert stats.bytes_in == len(stream)
        assert stats.samples == len(samples) and stats.invalid_samples == sum(not s.valid for s in samples)
        assert 0 <= stats.bytes_dropped <= stats.bytes_in
        assert stats.frames_ok >= 0 and stats.frames_bad >= 0 and not d._buf


# ------------------------------------------------------------------------------------ readers


@contextlib.contextmanager
def _no_hang(seconds: float = HANG_S) -> Iterator[None]:
    """Fail (TimeoutError) if the block runs longer than ``seconds``: a FIFO or a loop would."""
    def alarm(*_: object) -> None:
        raise TimeoutError(f"reader still running after {seconds} s")

    old = signal.signal(signal.SIGALRM, alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


def _only_user_errors(read: Callable[[], object]) -> None:
    """Run ``read``: it returns, or raises a one-line UserError; anything else fails the test."""
    with _no_hang():
        try:
            read()
        except UserError as exc:
            assert "\n" not in str(exc), str(exc)


@pytest.fixture(scope="module")
def workdir(tmp_path_factory: pytest.TempPathFactory, make_bundle) -> Path:
    """A session copy and a model folder that each example rewrites one file of."""
    from tests.annotate.machine_helpers import write_fake_machine

    root = tmp_path_factory.mktemp("fuzz")
    shutil.copytree(SESSION, root / "s", ignore=shutil.ignore_patterns("video.avi", "serial"))
    write_work(root / "s")  # the session's work.csv as `effortface work` writes it (issue 37)
    (root / "s" / "serial").mkdir()
    shutil.copy(SESSION / "serial" / "hrmi.serlog", root / "s" / "serial")
    write_bundle(make_bundle(), root / "m")
    model = json.loads((root / "m" / "model.json").read_text())  # with the rest anchor train writes
    model["rest_anchor"] = {"features": [0, 0, 0, 0], "at_rest": [0.1, 0.05, 0.2, 0.0], "level": [0.0] * 4,
                            "raters_rest_level": [0.02, None, 0.1, 0.0]}
    (root / "m" / "model.json").write_text(json.dumps(model))
    (root / "motion").mkdir()
    index = json.loads(MOTION_JSON.read_text())  # a version 2 entry with a mapping, as motion attach writes
    index["version"] = 2
    index["files"][0].update(unit_m=0.0254, up="y", mapping={"version": 2, "head": ["Neck1", "Head_end"],
                                                            "left_thigh": ["LeftUpLeg", "LeftLeg"]})
    (root / "motion" / "motion.json").write_text(json.dumps(index))
    shutil.copy(ROOT / "tests" / "data" / "motion" / "amp_humanoid_run.npz", root / "motion" / "clip.npz")
    write_fake_machine(root / "s")
    shutil.copytree(ROOT / "sample_sessions" / "reliability", root / "rel")
    poses = (root / "rel" / "poses.csv").read_text().replace("P01_20260112-093000_cardio", SESSION.name)
    (root / "rel" / "poses.csv").write_text(poses)  # poses of the fuzzed session, checked against its frames
    shutil.copy(DEFAULT_MODEL, root / "face_landmarker.task")
    return root


def _poses(path: Path) -> object:
    return read_poses(path, frames_by_session([path.parent.parent / "s"]))


def _motion_index(path: Path) -> object:
    """motion.json's entries and each entry's mapping as ``work`` reads them."""
    return [_segment_mapping(entry.get("mapping"), path) for entry in read_motion_index(path)]


def _task_bundle(path: Path) -> object:
    """A Face Landmarker bundle read and, where its runtime is installed, its three models loaded."""
    import importlib.util

    if importlib.util.find_spec("ai_edge_litert") is None:
        return read_landmarker_bundle(path)
    return FaceLandmarker(path)


#: file (relative to the work folder) -> the reader that must cope with it
READERS: dict[str, Callable[[Path], object]] = {
    "s/session.json": lambda p: read_session_info(p.parent),
    "s/events.csv": read_events,
    "s/heart_rate.csv": read_hr_csv,
    "s/video_frames.csv": read_video_frames,
    "s/work.csv": read_work_csv,
    "s/annotations/R1.json": lambda p: read_annotations(p, session_id=SESSION.name, rater="R1"),
    "s/serial/hrmi.serlog": read_serlog,
    "m/model.json": lambda p: read_bundle(p.parent),
    "m/svr.npz": lambda p: read_bundle(p.parent),
    "motion/motion.json": _motion_index,
    "motion/clip.npz": read_motion,
    # issue 37: the machine track and its sidecar, the blind round's CSVs, the .task bundle
    "s/machine/face_landmarker.csv": lambda p: read_machine_track(p.parent.parent),
    "s/machine/face_landmarker.json": lambda p: read_machine_track(p.parent.parent),
    "rel/poses.csv": _poses,
    "rel/ratings.csv": lambda p: read_ratings(p, DEFAULT_SET),
    "face_landmarker.task": _task_bundle,
}
ORIGINALS: dict[str, bytes] = {}


def _original(workdir: Path, name: str) -> bytes:
    if name not in ORIGINALS:
        ORIGINALS[name] = (workdir / name).read_bytes()
    return ORIGINALS[name]


@pytest.mark.parametrize("name", list(READERS))
@FUZZ
@given(data=st.data())
def test_readers_raise_only_user_errors_on_mutated_bytes(workdir: Path, name: str, data: st.DataObject) -> None:
    original = _original(workdir, name)
    path = workdir / name
    try:
        path.write_bytes(data.draw(mutated(original), label="file"))
        _only_user_errors(lambda: READERS[name](path))
    finally:
        path.write_bytes(original)


JSON_VALUES = st.recursive(
    st.none() | st.booleans() | st.integers(-2**70, 2**70) | st.sampled_from([10**400, -10**400])
    | st.floats(allow_nan=False) | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner, max_size=4),
    max_leaves=12,
)


def _paths(doc: object, prefix: tuple = ()) -> list[tuple]:
    """Every key/index path into a parsed JSON document."""
    out = [prefix]
    if isinstance(doc, dict):
        for k, v in doc.items():
            out += _paths(v, (*prefix, k))
    elif isinstance(doc, list):
        for i, v in enumerate(doc[:6]):
            out += _paths(v, (*prefix, i))
    return out


def _replace(doc: object, path: tuple, value: object) -> object:
    if not path:
        return value
    parent = doc
    for key in path[:-1]:
        parent = parent[key]  # type: ignore[index]
    parent[path[-1]] = value  # type: ignore[index]
    return doc


JSON_FILES = [n for n in READERS if n.endswith(".json")]


@pytest.mark.parametrize("name", JSON_FILES)
@FUZZ
@given(data=st.data())
def test_json_readers_raise_only_user_errors_on_any_field_value(workdir: Path, name: str,
                                                                 data: st.DataObject) -> None:
    original = _original(workdir, name)
    doc = json.loads(original)
    where = data.draw(st.sampled_from(_paths(doc)), label="field")
    _read_changed(workdir, name, original, _replace(doc, where, data.draw(JSON_VALUES, label="value")))


def _read_changed(workdir: Path, name: str, original: bytes, changed: object) -> None:
    """Write ``changed`` over the file ``name``, read it (only UserErrors), put the original back."""
    path = workdir / name
    try:
        path.write_text(json.dumps(changed))
        _only_user_errors(lambda: READERS[name](path))
    finally:
        path.write_bytes(original)


#: issue 37: JSON sections fuzzed on their own (a random field of the whole file rarely lands in them)
SECTIONS = {"m/model.json": ("output_filter", "rest_anchor"), "motion/motion.json": ("files",)}


@pytest.mark.parametrize("name", list(SECTIONS))
@FUZZ
@given(data=st.data())
def test_json_sections_raise_only_user_errors_on_any_value(workdir: Path, name: str, data: st.DataObject) -> None:
    original = _original(workdir, name)
    doc = json.loads(original)
    inside = [p for p in _paths(doc) if p and p[0] in SECTIONS[name]]
    where = data.draw(st.sampled_from(inside), label="field")
    _read_changed(workdir, name, original, _replace(doc, where, data.draw(JSON_VALUES, label="value")))
