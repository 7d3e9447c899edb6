"""``effortface serve``: the face, live, from work or motion streamed by another program.

Inputs (one per server):

- ``lsl`` type ``EffortWork``: channels ``w_per_kg, p_per_kg`` (W/kg), each sample one frame; the
  frame time is the difference of the sample time stamps.
- ``lsl`` type ``MoCap``: ``3 J`` channels (joint x, y, z in metres, Z up, joint by joint in the
  order of a skeleton file, see :mod:`effortface.train.motion_csv`), with ``--skeleton FILE``; work
  and power are computed here with the causal filter.
- ``osc``: messages ``/effortface/work w_per_kg p_per_kg [dt_s]`` on a UDP port.

Outputs (any of them):

- ``lsl``: a stream of type ``FaceWeights``, one float32 channel per blendshape (in the model's
  order), then ``nhr`` and ``hr_bpm``, at the input's nominal rate, time-stamped with the input
  sample's time stamp (so a consumer can measure the latency).
- ``osc``: ``/effortface/face`` with the same values, to ``HOST:PORT``.
- ``livelink``: Live Link Face packets over UDP to ``HOST:PORT`` (:func:`livelink_packet`): frame
  times from the input time stamps at the input's nominal rate (:func:`livelink_frame_time`), a
  stable UUID-style device id per subject name (:func:`livelink_device_id`).

The server survives its input disappearing: a lost LSL inlet is dropped and the stream is resolved
again (by name, or by type), and the character's state carries on. Every ``report_s`` it prints the
input and output rates.
"""

from __future__ import annotations

import dataclasses
import math
import socket
import struct
import sys
import threading
import time
from collections.abc import Callable, Sequence
from typing import IO, Any

import numpy as np

from effortface.core.errors import UserError
from effortface.train.face import apply_expressiveness
from effortface.train.motion import motion_from_positions
from effortface.train.motion_csv import read_skeleton
from effortface.train.physiology import PhysiologyState
from effortface.train.runtime import Character, FaceModel

EFFORT_WORK_TYPE = "EffortWork"
MOCAP_TYPE = "MoCap"
FACE_WEIGHTS_TYPE = "FaceWeights"
OSC_WORK_ADDRESS = "/effortface/work"
OSC_FACE_ADDRESS = "/effortface/face"
#: Live Link Face's 52 ARKit curves + head and eye rotations: the packet carries 61 floats
LIVELINK_COUNT = 61
#: frame steps outside this range (s) are replaced by the nominal step (a reconnect, a stall)
MAX_DT_S = 1.0


@dataclasses.dataclass
class ServeStats:
    """Counters of a running server (read by the rate printer and the tests)."""

    received: int = 0
    sent: int = 0
    connects: int = 0
    losses: int = 0


class FaceProcessor:
    """One character's state: an input frame (work or joint positions) -> the output row.

    Parameters
    ----------
    model : FaceModel
    character : Character
    skeleton : str, optional
        A skeleton file with ``rest_positions_m`` (MoCap input); None for EffortWork input.
    fps : float
        Nominal frame rate (the causal filter of MoCap input, the first frame step).
    mapping : str, optional
        A joint-to-segment mapping file for the skeleton's joints (MoCap input; default: the
        built-in conventions).
    """

    def __init__(self, model: FaceModel, character: Character, skeleton: str | None = None,
                 fps: float = 120.0, mapping: str | None = None) -> None:
        self.model = model
        self.fps = fps
        self.n_joints = 0
        if skeleton is None:
            self._stream: Any = WorkStream(model, character)
        else:
            skel = read_skeleton(skeleton)
            if skel["rest_positions_m"] is None:
                raise UserError(f"--skeleton {skeleton}: expected rest_positions_m (a reference pose), found none")
            rest = motion_from_positions(skel["rest_positions_m"][None], skel["joints"], skel["parents"], fps,
                                         source=str(skeleton))
            self.n_joints = len(skel["joints"])
            self._stream = model.stream(character, rest, fps=fps, mapping=mapping)
        self.columns = tuple(model.blendshapes.names) + ("nhr", "hr_bpm")

    def step(self, values: Sequence[float], dt_s: float) -> list[float]:
        """Advance one frame; return the blendshape weights, then nhr and hr_bpm."""
        if not (0.0 < dt_s <= MAX_DT_S) or not math.isfinite(dt_s):
            dt_s = 1.0 / self.fps
        if self.n_joints:
            weights = self._stream.step(np.asarray(values, float).reshape(self.n_joints, 3), dt_s)
        else:
            weights = self._stream.step_work(float(values[0]), float(values[1]), dt_s)
        return [*map(float, weights), self._stream.last["nhr"], self._stream.last["hr_bpm"]]


class WorkStream:
    """One character stepped from work and power computed elsewhere (no skeleton needed).

    The same steps as :meth:`effortface.train.runtime.CharacterStream.step_work` (physiology, face
    model, expressiveness), which needs a skeleton to be built.
    """

    def __init__(self, model: FaceModel, character: Character) -> None:
        self.model = model
        self._e = model.expressiveness(character)
        self._state = PhysiologyState(model.physiology_params(character))
        self.last: dict[str, float] = {}

    def step_work(self, w_per_kg: float, p_per_kg: float, dt_s: float) -> np.ndarray:
        """Advance one frame -> blendshape weights (B,); :attr:`last` holds nhr and hr_bpm."""
        phys = self._state.step(w_per_kg, dt_s)
        x = np.array([[w_per_kg, p_per_kg, phys["nhr"], phys["epoc_norm"]]], dtype=float)
        self.last = {"nhr": float(phys["nhr"]), "hr_bpm": float(phys["hr_bpm"])}
        return apply_expressiveness(self.model.face.predict(x)[0], self._e)


# --------------------------------------------------------------------------- outputs

def livelink_device_id(subject: str) -> str:
    """A stable UUID-style device id for ``subject`` (``8-4-4-4-12`` upper-case hex, as Live Link Face
    sends its iPhone's identifier): the same subject name gives the same id on every run."""
    import uuid

    return str(uuid.uuid5(uuid.NAMESPACE_URL, f"effortface:livelink:{subject}")).upper()


def livelink_frame_time(t_s: float, rate_hz: float) -> tuple[int, float, int, int]:
    """Live Link frame time of ``t_s`` seconds at ``rate_hz``: (frame, sub-frame, numerator, denominator).

    The rate is the send rate (rounded to a whole frame rate; 29.97-style rates as n*1000/1001), so
    Unreal's timecode advances one frame per frame sent and runs at real time.
    """
    rate = max(1, int(round(rate_hz)))
    num, den = (rate * 1000, 1001) if abs(rate_hz - rate * 1000 / 1001) < 1e-3 and rate_hz != rate else (rate, 1)
    frames = max(0.0, t_s) * num / den
    whole = int(math.floor(frames + 1e-6))
    return whole, float(max(0.0, frames - whole)), num, den


def livelink_packet(subject: str, device_id: str, frame: int, fps: int,
                    curves: dict[str, float], *, sub_frame: float = 0.0, denominator: int = 1) -> bytes:
    """One Live Link Face UDP packet (the app's version-6 layout, big-endian).

    ``uint8 version=6``, device id and subject name (each ``int32 length`` + UTF-8), frame time
    (``int32 frame, float32 sub-frame, int32 rate numerator, int32 denominator``), ``uint8 count=61``
    and 61 ``float32`` in the Live Link Face column order
    (:data:`effortface.train.curves_io.LIVELINK_BLENDSHAPES` then the head and eye rotations);
    ``curves`` maps those names to values, every other one is 0.
    """
    from effortface.train.curves_io import LIVELINK_BLENDSHAPES, LIVELINK_ROTATIONS

    names = LIVELINK_BLENDSHAPES + LIVELINK_ROTATIONS
    values = [float(curves.get(n, 0.0)) for n in names]
    out = struct.pack(">B", 6)
    for text in (device_id, subject):
        raw = text.encode("utf-8")
        out += struct.pack(">i", len(raw)) + raw
    out += struct.pack(">ifii", frame, sub_frame, fps, denominator)
    return out + struct.pack(">B", LIVELINK_COUNT) + struct.pack(f">{LIVELINK_COUNT}f", *values)


def arkit_curves(model: FaceModel, row: Sequence[float]) -> dict[str, float]:
    """Our blendshape weights under their ARKit names (Live Link Face's capitalisation)."""
    out = {}
    for shape, value in zip(model.blendshapes.shapes, row):
        for name in shape.arkit:
            out[name[:1].upper() + name[1:]] = float(value)
    return out


def parse_host_port(option: str, text: str | None) -> tuple[str, int] | None:
    """``HOST:PORT`` -> (host, port); None stays None; a one-line error naming ``option`` otherwise."""
    if text is None:
        return None
    host, _, port = text.rpartition(":")
    if not host or not port.isdigit() or not 0 < int(port) < 65536:
        raise UserError(f"{option}: expected HOST:PORT (e.g. 127.0.0.1:9001), found {text!r}")
    return host, int(port)


class Outputs:
    """The chosen outputs; :meth:`send` pushes one row to each."""

    def __init__(self, model: FaceModel, kinds: Sequence[str], *, name: str, osc_to: tuple[str, int] | None,
                 livelink_to: tuple[str, int] | None, rate_hz: float = 60.0) -> None:
        self.model, self.kinds, self.name = model, tuple(kinds), name
        #: the send rate declared in the Live Link frame times (the input's nominal rate)
        self.rate_hz = rate_hz
        self.device_id = livelink_device_id(name)
        self._t0: float | None = None
        self._outlet: Any = None
        self._osc: Any = None
        self._sock: socket.socket | None = None
        self._livelink_to = livelink_to
        self._frame = 0
        if "osc" in self.kinds:
            from pythonosc.udp_client import SimpleUDPClient

            if osc_to is None:
                raise UserError("--osc-out: expected HOST:PORT for --output osc, found none")
            self._osc = SimpleUDPClient(*osc_to)
        if "livelink" in self.kinds:
            if livelink_to is None:
                raise UserError("--livelink-out: expected HOST:PORT for --output livelink, found none")
            self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)

    def open_lsl(self, columns: Sequence[str], srate_hz: float) -> None:
        """Create the FaceWeights outlet (once: consumers keep it across input reconnects)."""
        if "lsl" not in self.kinds or self._outlet is not None:
            return
        import pylsl

        info = pylsl.StreamInfo(self.name, FACE_WEIGHTS_TYPE, len(columns), srate_hz, "float32",
                                f"effortface:serve:{self.name}")
        chans = info.desc().append_child("channels")
        for c in columns:
            ch = chans.append_child("channel")
            ch.append_child_value("label", c)
            ch.append_child_value("unit", {"hr_bpm": "bpm"}.get(c, "normalized"))
        self._outlet = pylsl.StreamOutlet(info)

    def send(self, row: list[float], stamp: float) -> None:
        """Push one output row (time stamp: the input sample's)."""
        if self._outlet is not None:
            self._outlet.push_sample(row, stamp)
        if self._osc is not None:
            self._osc.send_message(OSC_FACE_ADDRESS, row)
        if self._sock is not None and self._livelink_to is not None:
            if self._t0 is None:
                self._t0 = stamp
            frame, sub, num, den = livelink_frame_time(stamp - self._t0, self.rate_hz)
            packet = livelink_packet(self.name, self.device_id, frame, num, arkit_curves(self.model, row),
                                     sub_frame=sub, denominator=den)
            self._sock.sendto(packet, self._livelink_to)
        self._frame += 1


# --------------------------------------------------------------------------- inputs

class LslInput:
    """An LSL inlet that is re-resolved whenever its stream is lost."""

    def __init__(self, stream_type: str, name: str | None) -> None:
        self.stream_type, self.name = stream_type, name
        self._inlet: Any = None
        self.srate_hz = 0.0
        self.channels = 0

    def _connect(self, stats: ServeStats) -> bool:
        import pylsl

        found = pylsl.resolve_bypred(f"type='{self.stream_type}'" + (f" and name='{self.name}'" if self.name else ""),
                                     1, 0.5)
        if not found:
            return False
        from pylsl.util import LostError, TimeoutError as LslTimeout

        newest = max(found, key=lambda info: info.created_at())  # not a stream that just went
        inlet = pylsl.StreamInlet(newest, max_buflen=10, recover=False)
        try:
            inlet.open_stream(2.0)
        except (LostError, LslTimeout):  # a stream that just went (the resolver still lists it)
            return False
        self._inlet = inlet
        self.srate_hz = newest.nominal_srate()
        self.channels = newest.channel_count()
        stats.connects += 1
        return True

    def pull(self, stats: ServeStats) -> tuple[list, list] | None:
        """Samples and time stamps available now (waiting up to 0.1 s); None while disconnected."""
        from pylsl.util import LostError

        if self._inlet is None and not self._connect(stats):
            return None
        try:
            first, stamp = self._inlet.pull_sample(timeout=0.1)
            if first is None:
                return [], []
            more, stamps = self._inlet.pull_chunk(timeout=0.0)
            return [first, *more], [stamp, *stamps]
        except LostError:
            self._inlet = None
            stats.losses += 1
            return None


class OscInput:
    """``/effortface/work w p [dt]`` messages on a UDP port."""

    def __init__(self, port: int, host: str = "127.0.0.1") -> None:
        from pythonosc.dispatcher import Dispatcher
        from pythonosc.osc_server import BlockingOSCUDPServer

        self._pending: list[tuple[list[float], float]] = []
        dispatcher = Dispatcher()
        dispatcher.map(OSC_WORK_ADDRESS, self._on_work)
        self._server = BlockingOSCUDPServer((host, port), dispatcher)
        self._server.timeout = 0.1
        self.port = self._server.server_address[1]
        self.srate_hz = 0.0
        self._last: float | None = None

    def _on_work(self, _address: str, *args: Any) -> None:
        now = time.monotonic()
        self._pending.append(([float(a) for a in args], now))

    def pull(self, stats: ServeStats) -> tuple[list, list]:
        """Messages received now (waiting up to 0.1 s for the first)."""
        self._server.handle_request()
        got, self._pending = self._pending, []
        return [v for v, _ in got], [t for _, t in got]

    def close(self) -> None:
        self._server.server_close()


# --------------------------------------------------------------------------- the loop

def serve(processor: FaceProcessor, source: Any, outputs: Outputs, *, stop: threading.Event,
          duration_s: float | None = None, report_s: float = 5.0, log: IO[str] = sys.stderr,
          stats: ServeStats | None = None, on_row: Callable[[list[float]], None] | None = None) -> ServeStats:
    """Run until ``stop`` is set or ``duration_s`` has passed; print the rates every ``report_s``.

    Parameters
    ----------
    processor : FaceProcessor
    source : LslInput or OscInput
    outputs : Outputs
    stop : threading.Event
    duration_s : float, optional
    report_s : float
        Seconds between two rate lines on ``log``.
    stats : ServeStats, optional
        Counters to update (a new one by default).
    on_row : callable, optional
        Called with each output row (tests, benchmarks).

    Returns
    -------
    ServeStats
    """
    stats = stats or ServeStats()
    start = time.monotonic()
    next_report, last_counts = start + report_s, (0, 0)
    last_stamp: float | None = None
    connected = False
    while not stop.is_set() and (duration_s is None or time.monotonic() - start < duration_s):
        got = source.pull(stats)
        if got is None:  # lost or not found yet: reset the frame clock, keep the state
            if connected:
                print("serve: input lost; waiting for it to come back", file=log, flush=True)
            connected, last_stamp = False, None
            continue
        if not connected and isinstance(source, LslInput):
            connected = True
            print(f"serve: input {source.stream_type} connected ({source.srate_hz:g} Hz nominal)", file=log, flush=True)
            if source.srate_hz > 0:
                processor.fps = outputs.rate_hz = source.srate_hz
            outputs.open_lsl(processor.columns, source.srate_hz)
        values, stamps = got
        for sample, stamp in zip(values, stamps):
            dt_s = (sample[2] if len(sample) > 2 and not processor.n_joints else
                    (stamp - last_stamp if last_stamp is not None else 1.0 / processor.fps))
            last_stamp = stamp
            row = processor.step(sample, dt_s)
            stats.received += 1
            outputs.send(row, stamp)
            stats.sent += 1
            if on_row is not None:
                on_row(row)
        now = time.monotonic()
        if now >= next_report:
            span = now - next_report + report_s
            print(f"serve: in {(stats.received - last_counts[0]) / span:.1f} Hz, out "
                  f"{(stats.sent - last_counts[1]) / span:.1f} Hz, connects {stats.connects}, "
                  f"losses {stats.losses}", file=log, flush=True)
            next_report, last_counts = now + report_s, (stats.received, stats.sent)
    return stats
