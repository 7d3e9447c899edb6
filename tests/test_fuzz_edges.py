"""Fuzzing the edges issue 29 hardened, with hypothesis (marker ``fuzz``: the ``.ci/fuzz`` job runs it).

Fixed seed (``derandomize``), :data:`EXAMPLES` examples per property. The promises:

- ``serve``'s sample check takes any value and returns None or finite floats within their bounds;
  a raw OSC datagram of any bytes never raises; a server fed any mix of samples only ever emits
  finite rows with weights in [0, 1];
- ``.serlog``: any mutation of a real log reads without raising (or one UserError line), and the
  records read, the damaged bytes skipped and the torn tail account for every byte;
- BVH headers (joint depth, frame count, frame time) and XDF files (mutated headers and chunks) are
  read, or refused with one UserError line, never another exception, a hang or a half session;
- a mutated MJPG AVI (a crashed capture's video) is rewritten by ``recover``'s video copy without
  raising or hanging, and every frame it keeps decodes.
"""

from __future__ import annotations

import math
import os
import struct
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from effortface.capture_tool.avi_writer import MjpgAviWriter, mjpg_frames
from effortface.capture_tool.camera import rewrite_video
from effortface.capture_tool.serlog import MAGIC, read_serlog
from effortface.core.bounds import BOUNDS
from effortface.core.errors import UserError
from effortface.core.opencv import import_cv2
from effortface.interop.serve import FaceProcessor, ServeStats, check_sample, parse_work_datagram
from effortface.synth.motion import read_bvh

from tests.test_fuzz import _no_hang, _only_user_errors, mutated

pytestmark = pytest.mark.fuzz

ROOT = Path(__file__).resolve().parents[1]
SERLOG = ROOT / "sample_sessions" / "P03_20260113-094400_cardio" / "serial" / "hrmi.serlog"
EXAMPLES = int(os.environ.get("EFFORTFACE_FUZZ_EXAMPLES", "120"))
FUZZ = settings(max_examples=EXAMPLES, deadline=None, database=None,
                derandomize=os.environ.get("EFFORTFACE_FUZZ_RANDOM") != "1",
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])

ANY_VALUE = st.one_of(st.floats(), st.integers(-(10 ** 30), 10 ** 30), st.booleans(), st.none(), st.text(max_size=5),
                      st.binary(max_size=5))
SAMPLES = st.one_of(st.lists(ANY_VALUE, max_size=8), st.lists(st.floats(-50, 50), min_size=2, max_size=3), ANY_VALUE)


# ---------------------------------------------------------------------------------------- serve


@FUZZ
@given(values=SAMPLES, n_joints=st.sampled_from([0, 1, 2]))
def test_check_sample_takes_anything(values, n_joints) -> None:
    out = check_sample(values, n_joints)
    if out is not None:
        assert len(out) == (3 * n_joints if n_joints else len(out)) and all(math.isfinite(v) for v in out)
        assert all(abs(v) <= BOUNDS["position_m" if n_joints else "w_per_kg"].high for v in out[:2])


def _osc(values: list) -> bytes:
    from pythonosc.osc_message_builder import OscMessageBuilder

    builder = OscMessageBuilder("/effortface/work")
    for v in values:
        builder.add_arg(v, "d" if isinstance(v, float) else None)
    return builder.build().dgram


@FUZZ
@given(data=st.data())
def test_any_osc_datagram_is_parsed_or_counted(data: st.DataObject) -> None:
    seed = _osc(data.draw(st.lists(st.one_of(st.floats(), st.integers(-(2 ** 31), 2 ** 31 - 1), st.text(max_size=4)),
                                   max_size=4)))
    datagram = data.draw(st.one_of(mutated(seed), mutated(b"#bundle\0" + bytes(8) + struct.pack(">i", len(seed)) + seed),
                                   st.binary(max_size=200)))
    stats = ServeStats()
    messages = parse_work_datagram(datagram, stats)
    assert isinstance(messages, list) and stats.bad >= 0
    for params in messages:
        check_sample(params)  # whatever arrived, the check takes it


@pytest.fixture(scope="module")
def processor() -> FaceProcessor:
    from effortface.synth.runtime import Character, load_model

    return FaceProcessor(load_model("default"), Character(), fps=120)


@FUZZ
@given(samples=st.lists(SAMPLES, max_size=30), dts=st.lists(st.floats(), max_size=30))
def test_the_server_state_is_never_poisoned(processor: FaceProcessor, samples, dts) -> None:
    for k, sample in enumerate(samples):
        checked = check_sample(sample)
        if checked is None:
            continue
        row = processor.step(checked, dts[k] if k < len(dts) else 1 / 120)
        if row is not None:
            assert all(math.isfinite(v) for v in row) and all(0.0 <= w <= 1.0 for w in row[:-2])
    row = processor.step([10.0, 15.0], 1 / 120)  # a good sample after any history gives a good row
    assert row is not None and all(math.isfinite(v) for v in row)


# --------------------------------------------------------------------------------------- serlog


@FUZZ
@given(data=st.data())
def test_a_mutated_serlog_accounts_for_every_byte(data: st.DataObject, tmp_path_factory) -> None:
    blob = SERLOG.read_bytes()[:6000]
    head = blob.index(b"\n", len(MAGIC)) + 1
    body = data.draw(mutated(blob[head:]), label="records")
    path = tmp_path_factory.mktemp("serlog") / "x.serlog"
    path.write_bytes(blob[:head] + body)
    with _no_hang():
        log = read_serlog(path)
    used = sum(13 + len(r.payload) for r in log.records)
    assert used + log.skipped_bytes + log.truncated_bytes == len(body)
    assert all(r.kind in (0, 1) and math.isfinite(r.t_s) for r in log.records)
    assert (log.damage_warning() is None) == (log.skipped_bytes == 0)


# ----------------------------------------------------------------------------------------- AVI


@pytest.fixture(scope="module")
def recorded_avi(tmp_path_factory) -> tuple[bytes, list[bytes]]:
    """A 6-frame MJPG AVI as a killed capture leaves it (no index), and its frames' JPEG bytes."""
    path = tmp_path_factory.mktemp("avi") / "live.avi"
    writer = MjpgAviWriter(path, 15.0, (32, 24), quality=50)
    for k in range(6):
        writer.write(np.full((24, 32, 3), 40 * k, np.uint8))
    blob = path.read_bytes()
    writer.release()
    return blob, list(mjpg_frames(path))


@FUZZ
@given(data=st.data())
def test_a_mutated_avi_is_copied_frame_by_frame_or_not_at_all(data: st.DataObject, recorded_avi,
                                                               tmp_path_factory) -> None:
    blob, _ = recorded_avi  # (the exact copy of the recorded JPEGs is tested in test_camera.py)
    folder = tmp_path_factory.mktemp("avi")
    (folder / "cut.avi").write_bytes(data.draw(mutated(blob), label="avi"))
    with _no_hang():
        n = rewrite_video(folder / "cut.avi", folder / "fixed.avi")
    kept = list(mjpg_frames(folder / "fixed.avi")) if n else []
    assert len(kept) == n
    cv2 = import_cv2()
    assert all(cv2.imdecode(np.frombuffer(jpeg, np.uint8), cv2.IMREAD_COLOR) is not None for jpeg in kept)


# ----------------------------------------------------------------------------------------- BVH


def _bvh(depth: int, frames: str, frame_time: str, rows: int) -> str:
    head = ["HIERARCHY", "ROOT r", "{", "OFFSET 0 0 0", "CHANNELS 6 Xposition Yposition Zposition Zrotation "
            "Xrotation Yrotation"]
    head += [f"JOINT j{k} {{ OFFSET 0 10 0 CHANNELS 3 Zrotation Xrotation Yrotation" for k in range(depth)]
    head += ["End Site { OFFSET 0 10 0 }", "}" * (depth + 1), "MOTION", f"Frames: {frames}",
             f"Frame Time: {frame_time}"]
    return "\n".join(head + [" ".join(["0.5"] * (6 + 3 * depth))] * rows) + "\n"


NUMBER_TEXT = st.one_of(st.integers(-5, 10 ** 12).map(str), st.floats().map(repr),
                        st.sampled_from(["1e-300", "1e300", "nan", "inf", "-0", "0.0083333", "x", ""]))


@FUZZ
@given(depth=st.one_of(st.integers(0, 20), st.integers(150, 400)), frames=NUMBER_TEXT, frame_time=NUMBER_TEXT,
       rows=st.integers(0, 5))
def test_bvh_headers_are_read_or_refused_in_one_line(depth, frames, frame_time, rows, tmp_path_factory) -> None:
    path = tmp_path_factory.mktemp("bvh") / "clip.bvh"
    path.write_text(_bvh(depth, frames, frame_time, rows))

    def read() -> None:
        motion = read_bvh(path, unit_m=0.01)
        assert np.isfinite(motion.positions_m).all() and 0 < motion.fps < math.inf

    _only_user_errors(read)


# ----------------------------------------------------------------------------------------- XDF


def _seed_xdf() -> bytes:
    from tests.interop.xdf_writer import XdfStream, write_xdf

    with tempfile.TemporaryDirectory() as tmp:
        hr = XdfStream("Polar", "HeartRate", [("hr_bpm", "bpm"), ("rr_ms", "ms")], [5000.0 + k for k in range(12)],
                       [[70.0 + k, 800.0] for k in range(12)])
        work = XdfStream("w", "EffortWork", [("w_per_kg", "W/kg"), ("p_per_kg", "W/kg")], [5000.5, 5001.5],
                         [[1.0, 2.0], [1.5, 2.5]])
        events = XdfStream("events", "Markers", [("event", "")], [5002.0], [['{"kind": "marker"}']], fmt="string")
        return write_xdf(Path(tmp) / "r.xdf", [hr, work, events]).read_bytes()


XDF_SEED = _seed_xdf()


@FUZZ
@given(data=st.data())
def test_a_mutated_xdf_imports_or_is_refused_leaving_no_half_session(data: st.DataObject, tmp_path_factory) -> None:
    from effortface.core.session.folder import Participant
    from effortface.interop.xdf_import import import_xdf

    tmp = tmp_path_factory.mktemp("xdf")
    (tmp / "r.xdf").write_bytes(data.draw(mutated(XDF_SEED), label="xdf"))
    out = tmp / "sessions"
    try:
        with _no_hang(30.0):
            folder = import_xdf(tmp / "r.xdf", out, Participant("P01"))
    except UserError as exc:
        assert "\n" not in str(exc)
        assert not out.exists() or list(out.iterdir()) == []  # nothing half-written
        return
    assert (folder / "session.json").is_file() and [p.name for p in out.iterdir()] == [folder.name]
