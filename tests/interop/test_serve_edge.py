"""Issue 29: ``serve`` validates at the edge and never dies from its input; options are checked first.

Malformed OSC messages and raw datagrams, NaN/inf/huge values, LSL streams of the wrong width or with
string channels, a MoCap stream with NaN frames: each is dropped and counted (``bad N``), the server
stays up and every row it sends is finite with weights in [0, 1].
"""

from __future__ import annotations

import io
import json
import math
import socket
import subprocess
import sys
import threading
import time

import numpy as np
import pylsl
import pytest
from pythonosc.osc_message_builder import OscMessageBuilder

from effortface.interop.serve import (FaceProcessor, LslInput, OscInput, Outputs, ServeStats, StreamFinder,
                                            check_sample, serve, xpath_literal)
from effortface.synth.runtime import Character, load_model

from .lsl_helpers import unique


def _effortface(*args: str) -> list[str]:
    return [sys.executable, "-m", "effortface", *args]


def _osc(address: str, *values: object) -> bytes:
    builder = OscMessageBuilder(address)
    for v in values:
        builder.add_arg(v, "d" if isinstance(v, float) and abs(v) > 1e38 else None)
    return builder.build().dgram


@pytest.mark.parametrize(("values", "n_joints", "ok"), [
    ([12.0, 18.0], 0, True), ([12, 18, 1 / 60], 0, True), ([], 0, False), ([1.0], 0, False),
    ([1.0, 2.0, 3.0, 4.0], 0, False), (["a", "b"], 0, False), ([True, 1.0], 0, False),
    ([math.nan, 1.0], 0, False), ([1.0, math.inf], 0, False), ([1e308, 1.0], 0, False),
    ([1.0, 2.0, math.nan], 0, False), ("12", 0, False), (None, 0, False),
    ([0.1] * 6, 2, True), ([0.1] * 5, 2, False), ([0.1] * 5 + [math.nan], 2, False), ([0.1] * 5 + [1e200], 2, False),
])
def test_check_sample(values, n_joints, ok) -> None:
    assert (check_sample(values, n_joints) is not None) == ok


def _run(processor: FaceProcessor, source, seconds: float = 30.0) -> tuple[ServeStats, list, threading.Event,
                                                                            threading.Thread]:
    rows: list[list[float]] = []
    stats, stop = ServeStats(), threading.Event()
    outputs = Outputs(processor.model, [], name="t", osc_to=None, livelink_to=None)
    worker = threading.Thread(target=serve, args=(processor, source, outputs),
                              kwargs={"stop": stop, "stats": stats, "duration_s": seconds, "on_row": rows.append,
                                      "log": io.StringIO()}, daemon=True)
    worker.start()
    return stats, rows, stop, worker


def test_osc_garbage_is_counted_and_the_server_lives() -> None:
    model = load_model("default")
    source = OscInput(0)
    stats, rows, stop, worker = _run(FaceProcessor(model, Character(), fps=60), source)
    bad = [_osc("/effortface/work"), _osc("/effortface/work", 1.0), _osc("/effortface/work", "a", "b"),
           _osc("/effortface/work", math.nan, 1.0), _osc("/effortface/work", math.inf, 1.0),
           _osc("/effortface/work", 1e308, 1.0), _osc("/effortface/work", 1.0, 2.0, 3.0, 4.0),
           _osc("/other", 1.0, 2.0), b"\x00garbage", b"#bundle\x00" + b"\xff" * 12, b"/effortface/work\x00\x00\x00\x00,ff",
           b""]
    client = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        for k in range(20):
            client.sendto(_osc("/effortface/work", 20.0, 25.0, 1 / 60), ("127.0.0.1", source.port))
            client.sendto(bad[k % len(bad)], ("127.0.0.1", source.port))
        deadline = time.monotonic() + 20
        while (stats.sent < 20 or stats.bad < 20) and time.monotonic() < deadline:
            time.sleep(0.05)
    finally:
        stop.set()
        worker.join(10)
        client.close()
        source.close()
    assert not worker.is_alive()
    assert stats.sent == stats.received == 20 and stats.bad == 20
    weights = np.array(rows)[:, :-2]
    assert np.isfinite(rows).all() and ((weights >= 0) & (weights <= 1)).all()


class _Frames:
    """An input that yields a fixed list of (sample, stamp) once, then nothing (the LSL/OSC protocol)."""

    def __init__(self, samples: list, stamps: list) -> None:
        self.samples, self.stamps, self.srate_hz = samples, stamps, 0.0

    def pull(self, stats: ServeStats) -> tuple[list, list]:
        out, self.samples, stamps, self.stamps = self.samples, [], self.stamps, []
        if not out:
            time.sleep(0.01)
        return out, stamps


def test_nan_mocap_frames_never_poison_the_state(shared_data, tmp_path) -> None:
    from effortface.synth.motion import read_motion

    clip = read_motion(shared_data / "motion/cmu_13_29_squats_120fps.bvh").slice_s(0, 1)
    skeleton = tmp_path / "cmu.skeleton.json"
    skeleton.write_text(json.dumps({"joints": list(clip.joint_names), "parents": [int(p) for p in clip.parents],
                                    "rest_positions_m": clip.positions_m[0].tolist()}))
    frames = [f.ravel().tolist() for f in clip.positions_m[:60]]
    nan_frame = [math.nan] * len(frames[0])
    samples = frames[:20] + [nan_frame] * 3 + [[math.inf] * len(frames[0]), [1e200] * len(frames[0]),
                                              frames[0][:-3], ["x"] * len(frames[0])] + frames[20:]
    stamps = [k / 120 for k in range(len(samples))]
    processor = FaceProcessor(load_model("default"), Character(), str(skeleton), fps=120)
    stats, rows, stop, worker = _run(processor, _Frames(samples, stamps), seconds=10)
    deadline = time.monotonic() + 20
    while stats.sent < 60 and time.monotonic() < deadline:
        time.sleep(0.02)
    stop.set()
    worker.join(10)
    assert stats.sent == 60 and stats.bad == 7
    assert np.isfinite(rows).all()
    # a step that still goes non-finite rebuilds the state instead of keeping it
    assert processor.step(nan_frame, 1 / 120) is None and processor.resets == 1
    again = processor.step(frames[0], 1 / 120)
    assert again is not None and np.isfinite(again).all()


def test_wrong_width_and_string_lsl_streams_are_refused_then_a_good_one_is_taken() -> None:
    name = unique("edge")
    log = io.StringIO()
    narrow = pylsl.StreamOutlet(pylsl.StreamInfo(name, "EffortWork", 1, 120, "float32", unique("n")))
    text = pylsl.StreamOutlet(pylsl.StreamInfo(name, "EffortWork", 2, 120, "string", unique("s")))
    source = LslInput("EffortWork", name, (2, 3), log=log)
    stats = ServeStats()
    deadline = time.monotonic() + 20
    while log.getvalue().count("ignored") < 2 and time.monotonic() < deadline:
        assert source.pull(stats) is None  # refused: still waiting
    assert "expected 2 or 3 numeric channels, found 1 channels" in log.getvalue()
    assert "found 2 string channels" in log.getvalue()
    good = pylsl.StreamOutlet(pylsl.StreamInfo(name, "EffortWork", 2, 120, "float32", unique("g")))
    while source.pull(stats) is None and time.monotonic() < deadline:
        pass
    assert source.channels == 2 and stats.connects == 1
    assert log.getvalue().count("ignored") == 2  # each refused stream is told once
    del narrow, text, good


def _wait_for(condition, seconds: float = 20.0) -> bool:
    deadline = time.monotonic() + seconds
    while not condition() and time.monotonic() < deadline:
        time.sleep(0.01)
    return condition()


def test_the_finder_lists_a_returning_stream_forgets_a_gone_one_and_rests_when_unwatched() -> None:
    name = unique("finder")
    finder = StreamFinder(LslInput("EffortWork", name).query())
    assert finder.listed() == []  # nothing answered yet; the first call starts the asking
    first = pylsl.StreamOutlet(pylsl.StreamInfo(name, "EffortWork", 2, 120, "float32", unique("a")))
    first_uid = first.get_info().uid()
    assert _wait_for(lambda: [i.uid() for i in finder.listed()] == [first_uid])
    second = pylsl.StreamOutlet(pylsl.StreamInfo(name, "EffortWork", 2, 120, "float32", unique("b")))
    second_uid = second.get_info().uid()
    assert _wait_for(lambda: {i.uid() for i in finder.listed()} == {first_uid, second_uid})  # both, merged
    del first
    assert _wait_for(lambda: [i.uid() for i in finder.listed()] == [second_uid])  # the gone one forgotten
    assert _wait_for(lambda: not finder._wake.is_set())  # unwatched: it stops asking the network
    del second


def test_lsl_names_are_quoted_safely() -> None:
    assert xpath_literal("plain") == "'plain'"
    assert xpath_literal("it's") == '"it\'s"'
    assert xpath_literal("a'b\"c") == "concat('a', \"'\", 'b\"c')"
    hostile = "x' or type='EffortWork"
    other = pylsl.StreamOutlet(pylsl.StreamInfo(unique("other"), "EffortWork", 2, 120, "float32", unique("o")))
    assert pylsl.resolve_bypred(LslInput("EffortWork", hostile).query(), 0, 1.0) == []  # matches no other stream
    assert pylsl.resolve_bypred(LslInput("EffortWork", "it's").query(), 0, 0.5) == []  # and does not hang
    del other


def test_a_second_server_of_the_same_name_is_warned() -> None:
    name = unique("twin")
    model = load_model("default")
    first = Outputs(model, ["lsl"], name=name, osc_to=None, livelink_to=None, log=io.StringIO())
    first.open_lsl(["a", "b"], 60.0)
    log = io.StringIO()
    Outputs(model, ["lsl"], name=name, osc_to=None, livelink_to=None, log=log).open_lsl(["a", "b"], 60.0)
    assert f"warning: a FaceWeights stream named {name!r} is already published" in log.getvalue()
    assert "already published" not in first.log.getvalue()


@pytest.mark.parametrize(("args", "match"), [
    (["--input", "osc", "--osc-in-port", "99999"], "--osc-in-port: expected a number from 0 to 65535, found 99999"),
    (["--fps", "0"], "--fps: expected a number above 0 and at most 1000 Hz, found 0"),
    (["--fps", "nan"], "--fps: expected a number above 0 and at most 1000 Hz, found nan"),
    (["--report", "-1"], "--report: expected a number above 0 and at most 3600 s, found -1"),
    (["--duration", "inf"], "--duration: expected a number from 0 to 1e+06 s, found inf"),
    (["--output", "livelink", "--livelink-out", "no-such-host.invalid:9000"],
     "--livelink-out: expected a host name or address that resolves, found 'no-such-host.invalid'"),
])
def test_bad_options_are_refused_before_serving(args, match) -> None:
    out = subprocess.run(_effortface("serve", "default", *args, "--duration", "1") if "--duration" not in args
                         else _effortface("serve", "default", *args), capture_output=True, text=True, timeout=60)
    assert out.returncode == 2 and "Traceback" not in out.stderr, out.stderr
    assert out.stderr.strip().splitlines() == [f"effortface serve: {match}"] or match in out.stderr.strip(), out.stderr
    assert len(out.stderr.strip().splitlines()) == 1


def test_an_osc_port_in_use_is_one_line() -> None:
    taken = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    taken.bind(("127.0.0.1", 0))
    try:
        out = subprocess.run(_effortface("serve", "default", "--input", "osc", "--osc-in-port",
                                         str(taken.getsockname()[1]), "--duration", "1"),
                             capture_output=True, text=True, timeout=60)
    finally:
        taken.close()
    assert out.returncode == 2 and "Traceback" not in out.stderr
    assert "expected a free UDP port, found Address already in use" in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1
