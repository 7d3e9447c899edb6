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

from effortface.annotate.keyframes import read_annotations
from effortface.core.session.hr_csv import read_hr_csv
from effortface.capture_tool.protocols import PROTOCOLS, get_decoder
from effortface.capture_tool.protocols.encode import encode_line
from effortface.capture_tool.serlog import DATA, read_serlog
from effortface.core.session.folder import read_events, read_session_info, read_video_frames
from effortface.core.errors import UserError
from effortface.synth.bundle import read_bundle, write_bundle
from effortface.synth.work import read_motion_index, read_work_csv, write_work
from effortface.synth.motion import read_motion

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
    root = tmp_path_factory.mktemp("fuzz")
    shutil.copytree(SESSION, root / "s", ignore=shutil.ignore_patterns("video.avi", "serial"))
    write_work(root / "s")  # the session's work.csv as `effortface work` writes it (issue 37)
    (root / "s" / "serial").mkdir()
    shutil.copy(SESSION / "serial" / "hrmi.serlog", root / "s" / "serial")
    write_bundle(make_bundle(), root / "m")
    (root / "motion").mkdir()
    shutil.copy(MOTION_JSON, root / "motion" / "motion.json")
    shutil.copy(ROOT / "tests" / "data" / "motion" / "amp_humanoid_run.npz", root / "motion" / "clip.npz")
    return root


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
    "motion/motion.json": read_motion_index,
    "motion/clip.npz": read_motion,
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
    changed = _replace(doc, where, data.draw(JSON_VALUES, label="value"))
    path = workdir / name
    try:
        path.write_text(json.dumps(changed))
        _only_user_errors(lambda: READERS[name](path))
    finally:
        path.write_bytes(original)
