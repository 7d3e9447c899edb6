"""``effortface serve`` (Must show): an LSL EffortWork stream becomes FaceWeights at the input rate,
and the server recovers after its input stream is closed and reopened. Also OSC in/out and Live
Link Face packets, with the real pylsl and python-osc on loopback."""

from __future__ import annotations

import signal
import re
import socket
import struct
import subprocess
import sys
import threading
import time

import numpy as np
import pylsl
import pytest

from effortface.core.blendshapes import DEFAULT_SET
from effortface.interop.serve import (FaceProcessor, Outputs, OscInput, ServeStats, livelink_packet,
                                            parse_host_port, serve)
from effortface.synth.runtime import Character, load_model

from .lsl_helpers import WorkSender, pull_for, unique


def _effortface(*args: str) -> list[str]:
    return [sys.executable, "-m", "effortface", *args]


def _face_inlet(name: str) -> pylsl.StreamInlet:
    found = pylsl.resolve_byprop("name", name, 1, 20.0)
    assert found, f"no FaceWeights stream {name}"
    assert found[0].type() == "FaceWeights" and found[0].channel_count() == len(DEFAULT_SET.names) + 2
    inlet = pylsl.StreamInlet(found[0], max_buflen=30)
    inlet.open_stream(10)
    return inlet


def test_serve_turns_effort_work_into_face_weights_and_recovers(tmp_path):
    in_name, out_name = unique("work"), unique("face")
    sender = WorkSender(in_name, 120.0)
    proc = subprocess.Popen(_effortface("serve", "default", "--input", "lsl", "--input-name", in_name,
                                        "--output", "lsl", "--name", out_name, "--report", "1",
                                        "--training-level", "3"),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        inlet = _face_inlet(out_name)
        values, stamps = pull_for(inlet, 3.0)
        sent = [s for s in sender.stamps if stamps and stamps[0] <= s <= stamps[-1]]
        rate_out = (len(stamps) - 1) / (stamps[-1] - stamps[0])
        rate_in = (len(sent) - 1) / (sent[-1] - sent[0])       # what the sender managed on a busy machine
        assert rate_out == pytest.approx(rate_in, rel=1e-6) and rate_in > 90
        assert len(stamps) == len(sent)                            # one output per input sample
        np.testing.assert_allclose(stamps, sent, atol=1e-6)        # time-stamped with the input's stamps
        rows = np.array(values)
        assert np.all((rows[:, :4] >= 0) & (rows[:, :4] <= 1)) and np.all(rows[:, 5] > 40)
        hr_before = rows[-1, 5]
        sender.close()                                             # the input disappears...
        old_stamps = set(sender.stamps)
        time.sleep(2.0)
        sender = WorkSender(in_name, 120.0)                        # ...and comes back
        values2, stamps2 = [], []
        deadline = time.monotonic() + 40
        while sum(s not in old_stamps for s in stamps2) <= 200 and time.monotonic() < deadline:
            more_values, more_stamps = pull_for(inlet, 0.5)        # the server re-resolves the input
            values2, stamps2 = values2 + more_values, stamps2 + more_stamps
        # on a loaded machine the last outputs of the old input may still be in flight: they all
        # come first, and every later output answers a sample of the new input
        is_new = [s not in old_stamps for s in stamps2]
        assert sum(is_new) > 200 and is_new == sorted(is_new)
        assert set(s for s, new in zip(stamps2, is_new) if new) <= set(sender.stamps)
        first_new = is_new.index(True)
        assert np.array(values2)[first_new, 5] >= hr_before - 1.0  # the character's state carried on
    finally:
        sender.close()
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=30)
    assert proc.returncode == 0, err
    assert "input lost; waiting for it to come back" in err
    assert err.count("input EffortWork connected") == 2
    assert "serve: in " in err and " Hz, out " in err


def test_osc_in_to_osc_and_livelink_out():
    from pythonosc.dispatcher import Dispatcher
    from pythonosc.osc_server import ThreadingOSCUDPServer
    from pythonosc.udp_client import SimpleUDPClient

    got: list[list[float]] = []
    dispatcher = Dispatcher()
    dispatcher.map("/effortface/face", lambda _a, *v: got.append(list(v)))
    osc_out = ThreadingOSCUDPServer(("127.0.0.1", 0), dispatcher)
    threading.Thread(target=osc_out.serve_forever, daemon=True).start()
    ll_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    ll_sock.bind(("127.0.0.1", 0))
    ll_sock.settimeout(5)
    model = load_model("default")
    processor = FaceProcessor(model, Character(), fps=60)
    outputs = Outputs(model, ["osc", "livelink"], name="hero", osc_to=osc_out.server_address,
                      livelink_to=ll_sock.getsockname())
    source = OscInput(0)
    stop = threading.Event()
    stats = ServeStats()
    worker = threading.Thread(target=serve, args=(processor, source, outputs),
                              kwargs={"stop": stop, "stats": stats, "duration_s": 20}, daemon=True)
    worker.start()
    client = SimpleUDPClient("127.0.0.1", source.port)
    for _ in range(30):
        client.send_message("/effortface/work", [20.0, 25.0, 1 / 60])
        time.sleep(0.005)
    packet, _ = ll_sock.recvfrom(4096)
    deadline = time.monotonic() + 10
    while len(got) < 30 and time.monotonic() < deadline:
        time.sleep(0.05)
    stop.set()
    worker.join(10)
    source.close()
    osc_out.shutdown()
    assert stats.received == stats.sent == 30 and len(got) == 30
    assert len(got[-1]) == 6 and 0 <= got[-1][1] <= 1
    # Live Link Face v6: version, device id, subject, frame time, count, 61 big-endian floats
    assert packet[0] == 6
    n = struct.unpack(">i", packet[1:5])[0]
    assert re.fullmatch(rb"[0-9A-F-]{36}", packet[5:5 + n])
    k = 5 + n
    m = struct.unpack(">i", packet[k:k + 4])[0]
    assert packet[k + 4:k + 4 + m] == b"hero"
    body = packet[k + 4 + m + 16:]
    assert body[0] == 61 and len(body) == 1 + 61 * 4


def test_livelink_packet_puts_weights_under_arkit_names():
    from effortface.synth.curves_io import LIVELINK_BLENDSHAPES

    packet = livelink_packet("s", "d", 7, 60, {"JawOpen": 0.5, "BrowDownLeft": 0.25})
    floats = struct.unpack(">61f", packet[-61 * 4:])
    assert floats[LIVELINK_BLENDSHAPES.index("JawOpen")] == 0.5
    assert floats[LIVELINK_BLENDSHAPES.index("BrowDownLeft")] == 0.25 and sum(floats) == 0.75


@pytest.mark.parametrize(("args", "match"), [
    (["--output", "osc"], "--osc-out: expected HOST:PORT for --output osc, found none"),
    (["--output", "livelink", "--livelink-out", "nohost"], "--livelink-out: expected HOST:PORT"),
    (["--input-type", "MoCap"], "--skeleton: expected a skeleton file for --input-type MoCap"),
    (["--age", "5"], "character options: age: expected a number from 10 to 100"),
])
def test_bad_options_are_one_line(args, match):
    out = subprocess.run(_effortface("serve", "default", *args, "--duration", "1"), capture_output=True,
                         text=True, timeout=60)
    assert out.returncode == 2 and match in out.stderr and "Traceback" not in out.stderr
    assert parse_host_port("--x", "127.0.0.1:9") == ("127.0.0.1", 9)


def test_mocap_frames_give_the_runtime_stream_weights(shared_data, tmp_path):
    """MoCap input: joint positions + a skeleton file give what model.stream gives."""
    import json

    from effortface.synth.motion import read_motion

    clip = read_motion(shared_data / "motion/cmu_13_29_squats_120fps.bvh").slice_s(0, 2)
    skeleton = tmp_path / "cmu.skeleton.json"
    skeleton.write_text(json.dumps({"joints": list(clip.joint_names), "parents": [int(p) for p in clip.parents],
                                    "rest_positions_m": clip.positions_m[0].tolist()}))
    model = load_model("default")
    processor = FaceProcessor(model, Character(), str(skeleton), fps=clip.fps)
    rest = clip.slice_s(0, 1 / clip.fps)
    live = model.stream(Character(), rest, fps=clip.fps)
    for frame in clip.positions_m:
        row = processor.step(frame.ravel().tolist(), 1 / clip.fps)
        want = live.step(frame, 1 / clip.fps)
    np.testing.assert_allclose(row[:4], want, atol=1e-12)
    assert row[5] == pytest.approx(live.last["hr_bpm"])


def decode_livelink(packet: bytes) -> dict:
    """A Live Link Face UDP packet decoded independently, following Epic's layout (version 6,
    big-endian): uint8 version; FString device id and subject (int32 length + UTF-8); FQualifiedFrameTime
    (int32 frame, float32 sub-frame, FFrameRate int32 numerator, int32 denominator); uint8 count; floats."""
    version = packet[0]
    k = 1
    texts = []
    for _ in range(2):
        (n,) = struct.unpack_from(">i", packet, k)
        texts.append(packet[k + 4:k + 4 + n].decode("utf-8"))
        k += 4 + n
    frame, sub, num, den = struct.unpack_from(">ifii", packet, k)
    count = packet[k + 16]
    values = struct.unpack_from(f">{count}f", packet, k + 17)
    assert k + 17 + 4 * count == len(packet)
    return {"version": version, "device": texts[0], "subject": texts[1], "frame": frame, "sub": sub,
            "rate": num / den, "values": values}


@pytest.mark.parametrize("rate_hz", [120.0, 60.0, 29.97])
def test_livelink_frame_times_follow_the_send_rate(rate_hz):
    """Frame numbers count frames at the declared rate, the declared rate is the send rate: Unreal's
    timecode then runs at real time (before: 60 fps declared, one frame per packet at 120 Hz)."""
    import re

    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(5)
    model = load_model("default")
    outputs = Outputs(model, ["livelink"], name="hero", osc_to=None, livelink_to=sock.getsockname(), rate_hz=rate_hz)
    n = 90
    row = [0.5] * len(model.columns)
    for k in range(n):
        outputs.send(row, 5000.0 + k / rate_hz)
    packets = [decode_livelink(sock.recvfrom(4096)[0]) for _ in range(n)]
    sock.close()
    assert [p["frame"] for p in packets] == list(range(n))
    assert all(abs(p["rate"] - rate_hz) < 1e-3 and 0.0 <= p["sub"] < 1e-3 for p in packets)
    device = packets[0]["device"]
    assert re.fullmatch(r"[0-9A-F]{8}-[0-9A-F]{4}-[0-9A-F]{4}-[0-9A-F]{4}-[0-9A-F]{12}", device)
    assert {p["device"] for p in packets} == {device} and packets[0]["subject"] == "hero"
    again = Outputs(model, ["livelink"], name="hero", osc_to=None, livelink_to=("127.0.0.1", 9), rate_hz=rate_hz)
    assert again.device_id == device                                   # stable across runs
