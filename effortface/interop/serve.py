"""``effortface serve``: the face, live, from work or motion streamed by another program.

Inputs (one per server):

- ``lsl`` type ``EffortWork``: channels ``w_per_kg, p_per_kg`` (W/kg), each sample one frame; the
  frame time is the difference of the sample time stamps.
- ``lsl`` type ``MoCap``: ``3 J`` channels (joint x, y, z in metres, Z up, joint by joint in the
  order of a skeleton file, see :mod:`effortface.synth.motion_csv`), with ``--skeleton FILE``; work
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

Every sample is checked at the edge (issue 29) by :func:`check_sample`: its width (2 or 3 values for
work, ``3 J`` for MoCap), its types (numbers only, never a string or a bool) and its values (finite,
within :data:`effortface.core.bounds.BOUNDS`); a bad sample, an OSC datagram that does not parse or
carries another address, is dropped and counted (``bad N`` in the rate line), never fed to the
character. An LSL stream of the wrong width or with string channels is refused with one line (and
again after a reconnect). Should a step still give a non-finite row, the character's state is
rebuilt rather than poisoned, and the row is not sent: outputs are always finite, weights in [0, 1].
"""

from __future__ import annotations

import dataclasses
import math
import numbers
import select
import socket
import struct
import sys
import threading
import time
from collections.abc import Callable, Sequence
from typing import IO, Any

import numpy as np

from effortface.core.bounds import BOUNDS
from effortface.core.errors import UserError
from effortface.synth.face import apply_expressiveness
from effortface.synth.motion import UP_TO_Z_UP, detect_up_axis, motion_from_positions
from effortface.synth.motion_csv import read_skeleton
from effortface.synth.physiology import PhysiologyState
from effortface.synth.plausibility import check_read
from effortface.synth.read_options import MotionReadOptions
from effortface.synth.runtime import Character, FaceModel

EFFORT_WORK_TYPE = "EffortWork"
MOCAP_TYPE = "MoCap"
FACE_WEIGHTS_TYPE = "FaceWeights"
OSC_WORK_ADDRESS = "/effortface/work"
OSC_FACE_ADDRESS = "/effortface/face"
#: Live Link Face's 52 ARKit curves + head and eye rotations: the packet carries 61 floats
LIVELINK_COUNT = 61
#: frame steps outside this range (s) are replaced by the nominal step (a reconnect, a stall)
MAX_DT_S = 1.0
#: silence (s) after which the LSL input checks whether its source restarted as a new stream
SILENCE_PROBE_S = 0.3
#: pause (s) before looking again when no acceptable stream is listed (no busy loop)
REFUSED_WAIT_S = 0.02
#: a stream the finder has not heard from for this long (s) is no longer listed
RESOLVER_FORGET_S = 1.0
#: one query of the finder waits this long (s) for an answer when no stream answers
FINDER_QUERY_S = 0.2
#: the finder asks at most this often (s): a stream that answers at once does not make it spin
FINDER_PACE_S = 0.05
#: the finder keeps asking for this long (s) after the server last looked at its list
FINDER_IDLE_S = 1.0
#: datagrams read in one pull at most: a flood waits in the kernel's buffer, the loop keeps its pace
MAX_DATAGRAMS_PER_PULL = 1024
#: pylsl's channel format code of string channels
_LSL_STRING_FORMAT = 3


#: the outputs and inputs built in (:func:`output_names` and :func:`input_names` add registered ones)
BUILTIN_OUTPUTS = ("lsl", "osc", "livelink")
BUILTIN_INPUTS = ("lsl", "osc")
#: an output: factory(model, name) -> an object with ``send(row: list[float], stamp: float)``
OutputFactory = Callable[[FaceModel, str], Any]
#: an input: factory(options) -> an object with ``pull(stats)`` (``(values, stamps)``, or None while
#: disconnected) and ``srate_hz``; ``options`` is the command's parsed options
InputFactory = Callable[[Any], Any]
_OUTPUTS: dict[str, OutputFactory] = {}
_INPUTS: dict[str, InputFactory] = {}


def _check_name(kind: str, name: str, builtin: Sequence[str]) -> None:
    if not (isinstance(name, str) and name.isidentifier() and name.islower()) or name in builtin:
        raise ValueError(f"{kind} name: expected a new lower-case name (not {', '.join(builtin)}), found {name!r}")


def register_output(name: str, factory: OutputFactory) -> None:
    """Add a live output to ``effortface serve --output NAME`` and :class:`Outputs`.

    Parameters
    ----------
    name : str
        A lower-case identifier other than the built-in ones (:data:`BUILTIN_OUTPUTS`).
    factory : callable
        ``factory(model, name) -> sink``, called once per server; the server calls
        ``sink.send(row, stamp)`` for every output row (the blendshape weights in the model's
        order, then ``nhr`` and ``hr_bpm``; ``stamp`` is the input sample's time stamp).

    Raises
    ------
    ValueError
        A name that is not a lower-case identifier, or a built-in one.
    """
    _check_name("output", name, BUILTIN_OUTPUTS)
    _OUTPUTS[name] = factory


def register_input(name: str, factory: InputFactory) -> None:
    """Add a live input to ``effortface serve --input NAME`` (one per server).

    Parameters
    ----------
    name : str
        A lower-case identifier other than the built-in ones (:data:`BUILTIN_INPUTS`).
    factory : callable
        ``factory(options) -> source``; :func:`serve` calls ``source.pull(stats)``, which returns
        the frames received now as ``(values, stamps)`` (each value ``[w_per_kg, p_per_kg]``, or
        ``[w_per_kg, p_per_kg, dt_s]``, or the 3 J joint coordinates of MoCap input), or None while
        the source is disconnected. ``source.srate_hz`` is its nominal rate (0 if none).

    Raises
    ------
    ValueError
        A name that is not a lower-case identifier, or a built-in one.
    """
    _check_name("input", name, BUILTIN_INPUTS)
    _INPUTS[name] = factory


def output_names() -> tuple[str, ...]:
    """Every output ``--output`` accepts: the built-in ones, then the registered ones."""
    return BUILTIN_OUTPUTS + tuple(_OUTPUTS)


def input_names() -> tuple[str, ...]:
    """Every input ``--input`` accepts: the built-in ones, then the registered ones."""
    return BUILTIN_INPUTS + tuple(_INPUTS)


def make_input(name: str, options: Any) -> Any:
    """A registered input's source, made from the command's options (see :func:`register_input`)."""
    if name not in _INPUTS:
        raise UserError(f"--input: expected one of {', '.join(input_names())}, found {name!r}")
    return _INPUTS[name](options)


@dataclasses.dataclass
class ServeStats:
    """Counters of a running server (read by the rate printer and the tests)."""

    received: int = 0
    sent: int = 0
    connects: int = 0
    losses: int = 0
    #: samples and datagrams dropped at the edge (wrong width, type or value; unparsable; reset steps)
    bad: int = 0


def check_sample(values: object, n_joints: int = 0) -> list[float] | None:
    """One input sample as floats if it is well formed, else None (the caller drops and counts it).

    Parameters
    ----------
    values : object
        What the input carried: a sequence of numbers.
    n_joints : int
        0 for work input (``w_per_kg, p_per_kg[, dt_s]``), else the skeleton's joints (``3 J``
        positions in metres).

    Returns
    -------
    list of float or None
        None for a wrong width, a non-number (a string, a bool), a non-finite value, or a value
        outside its bound (``w_per_kg``/``p_per_kg``/``position_m`` in :data:`BOUNDS`; ``dt_s`` is
        only required to be finite: an unusual step is replaced by the nominal one).
    """
    if isinstance(values, (str, bytes)) or not isinstance(values, Sequence):
        return None
    if n_joints:
        names: Sequence[str] = ("position_m",) * (3 * n_joints)
        if len(values) != len(names):
            return None
    else:
        if len(values) not in (2, 3):
            return None
        names = ("w_per_kg", "p_per_kg", "")[:len(values)]
    out = []
    for name, value in zip(names, values):
        if not isinstance(value, numbers.Real) or isinstance(value, bool):
            return None
        number = float(value)
        if not math.isfinite(number) or (name and not BOUNDS[name].contains(number)):
            return None
        out.append(number)
    return out


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
    read : MotionReadOptions, optional
        ``--unit-m``, ``--up`` and ``--trust-skeleton`` for the skeleton and its frames (default:
        metres, the up axis from the rest pose's head and feet, Z when it names none). The rest
        pose goes through the plausibility gate.
    """

    def __init__(self, model: FaceModel, character: Character, skeleton: str | None = None,
                 fps: float = 120.0, mapping: str | None = None, read: MotionReadOptions | None = None) -> None:
        self.model = model
        self.character = character
        self.mapping = mapping
        self.fps = fps
        self.n_joints = 0
        self._rest: Any = None
        self._turn = np.eye(3)  # file axes and unit -> metres, Z up (each frame: positions @ turn.T)
        self.reading: dict[str, Any] = {}
        self.body: dict[str, Any] = {}
        if skeleton is not None:
            self._read_skeleton(skeleton, read or MotionReadOptions(mapping=mapping))
        self._stream: Any = self._new_stream()
        self.resets = 0
        self.columns = tuple(model.blendshapes.names) + ("nhr", "hr_bpm")

    def _read_skeleton(self, skeleton: str, read: MotionReadOptions) -> None:
        """The rest pose turned to metres and Z up (and the turn every frame gets), through the gate."""
        skel = read_skeleton(skeleton)
        if skel["rest_positions_m"] is None:
            raise UserError(f"--skeleton {skeleton}: expected rest_positions_m (a reference pose), found none")
        rest = np.asarray(skel["rest_positions_m"], dtype=float)
        up, up_from = (read.up, "given (--up)") if read.up is not None else \
            detect_up_axis(rest[None], skel["joints"], "z")
        unit_m, unit_from = (read.unit_m, "given (--unit-m)") if read.unit_m is not None else \
            (1.0, "the skeleton file (rest_positions_m: metres)")
        self._turn = UP_TO_Z_UP[up] * unit_m
        self.reading = {"unit_m": unit_m, "unit_from": unit_from, "up_axis": up, "up_from": up_from}
        self._rest = dataclasses.replace(
            motion_from_positions((rest @ self._turn.T)[None], skel["joints"], skel["parents"], self.fps,
                                  source=str(skeleton)), reading=self.reading)
        self.body = check_read(self._rest, dataclasses.replace(read, mapping=read.mapping or self.mapping))
        self.n_joints = len(skel["joints"])

    def _new_stream(self) -> Any:
        """A fresh character state (work input: :class:`WorkStream`; MoCap: the runtime's stream)."""
        if self._rest is None:
            return WorkStream(self.model, self.character)
        return self.model.stream(self.character, self._rest, fps=self.fps, mapping=self.mapping)

    def step(self, values: Sequence[float], dt_s: float) -> list[float] | None:
        """Advance one frame; return the blendshape weights (in [0, 1]), then nhr and hr_bpm.

        Returns None, and rebuilds the character's state, if the step gave a non-finite value (a
        state is never left poisoned); ``values`` should have passed :func:`check_sample`.
        """
        if not (0.0 < dt_s <= MAX_DT_S) or not math.isfinite(dt_s):
            dt_s = 1.0 / self.fps
        with np.errstate(all="ignore"):
            if self.n_joints:
                weights = self._stream.step(np.asarray(values, float).reshape(self.n_joints, 3) @ self._turn.T, dt_s)
            else:
                weights = self._stream.step_work(float(values[0]), float(values[1]), dt_s)
            row = [*map(float, np.clip(weights, 0.0, 1.0)), float(self._stream.last["nhr"]),
                   float(self._stream.last["hr_bpm"])]
        if not all(math.isfinite(v) for v in row) or not all(math.isfinite(float(w)) for w in weights):
            self._stream = self._new_stream()
            self.resets += 1
            return None
        return row


class WorkStream:
    """One character stepped from work and power computed elsewhere (no skeleton needed).

    The same steps as :meth:`effortface.synth.runtime.CharacterStream.step_work` (physiology, face
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
    (:data:`effortface.synth.curves_io.LIVELINK_BLENDSHAPES` then the head and eye rotations);
    ``curves`` maps those names to values, every other one is 0.
    """
    from effortface.synth.curves_io import LIVELINK_BLENDSHAPES, LIVELINK_ROTATIONS

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
                 livelink_to: tuple[str, int] | None, rate_hz: float = 60.0, log: IO[str] | None = None) -> None:
        self.model, self.kinds, self.name = model, tuple(kinds), name
        #: the send rate declared in the Live Link frame times (the input's nominal rate)
        self.rate_hz = rate_hz
        self.device_id = livelink_device_id(name)
        self._t0: float | None = None
        self.log = log if log is not None else sys.stderr
        self.send_failures = 0
        self._outlet: Any = None
        self._osc: Any = None
        self._sock: socket.socket | None = None
        self._livelink_to = livelink_to
        self._frame = 0
        unknown = [k for k in self.kinds if k not in output_names()]
        if unknown:
            raise UserError(f"--output: expected one of {', '.join(output_names())}, found {unknown[0]!r}")
        self._sinks = [_OUTPUTS[k](model, name) for k in self.kinds if k in _OUTPUTS]
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

        twins = pylsl.resolve_bypred(f"type='{FACE_WEIGHTS_TYPE}' and name={xpath_literal(self.name)}", 1, 0.5)
        if twins:
            print(f"serve: warning: a {FACE_WEIGHTS_TYPE} stream named {self.name!r} is already published (on "
                  f"{twins[0].hostname()}); consumers may take either: give this server another --name",
                  file=self.log, flush=True)
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
        try:
            if self._osc is not None:
                self._osc.send_message(OSC_FACE_ADDRESS, row)
            if self._sock is not None and self._livelink_to is not None:
                if self._t0 is None:
                    self._t0 = stamp
                frame, sub, num, den = livelink_frame_time(stamp - self._t0, self.rate_hz)
                packet = livelink_packet(self.name, self.device_id, frame, num, arkit_curves(self.model, row),
                                         sub_frame=sub, denominator=den)
                self._sock.sendto(packet, self._livelink_to)
            for sink in self._sinks:
                sink.send(row, stamp)
        except OSError as exc:  # a receiver that went (connection refused), a network down: keep serving
            self.send_failures += 1
            if self.send_failures == 1:
                print(f"serve: warning: could not send a row ({exc.strerror or exc}); later failures are "
                      "counted, not printed", file=self.log, flush=True)
        self._frame += 1


# --------------------------------------------------------------------------- inputs

def xpath_literal(text: str) -> str:
    """``text`` as an XPath string literal for an LSL query (a quote in a name can end no predicate)."""
    if "'" not in text:
        return f"'{text}'"
    if '"' not in text:
        return f'"{text}"'
    return "concat(" + ", \"'\", ".join(f"'{part}'" for part in text.split("'")) + ")"


def _discard(holder: list[Any]) -> None:
    """Destroy the LSL inlet in ``holder`` (its only reference) in a background thread.

    liblsl joins an inlet's receiver threads when it is destroyed, which takes seconds for a broken
    connection; done in the serving thread, that stalled the reconnect (up to 5 s in the soak).
    """
    threading.Thread(target=holder.clear, name="lsl-inlet-discard", daemon=True).start()


class StreamFinder:
    """Streams matching an LSL query, found by a background thread while someone looks for them.

    liblsl's continuous resolver sends a query wave only every ``ContinuousResolveInterval +
    MulticastMinRTT`` (1 s by default): a returning stream waited up to 1.2 s to be seen. A one-shot
    query that waits for one answer returns within milliseconds of a stream appearing, but blocks
    :data:`FINDER_QUERY_S` while none does; so it runs here, in a daemon thread, only while
    :meth:`listed` was called in the last :data:`FINDER_IDLE_S` (a lost or silent input), at most
    every :data:`FINDER_PACE_S`. Answers are merged and forgotten after :data:`RESOLVER_FORGET_S`, as
    the continuous resolver does, so a query that returned the old stream first still lists the new.

    Parameters
    ----------
    query : str
        An LSL predicate (see :meth:`LslInput.query`).
    """

    def __init__(self, query: str) -> None:
        self.query = query
        self._lock = threading.Lock()
        self._seen: dict[str, tuple[Any, float]] = {}  # uid -> (info, monotonic time last answered)
        self._wanted_at = 0.0
        self._wake = threading.Event()
        self._thread = threading.Thread(target=self._run, name="lsl-finder", daemon=True)
        self._thread.start()

    def listed(self) -> list[Any]:
        """The streams that answered in the last :data:`RESOLVER_FORGET_S`; keeps the finder asking."""
        now = time.monotonic()
        self._wanted_at = now
        self._wake.set()
        with self._lock:
            return [info for info, seen_at in self._seen.values() if now - seen_at <= RESOLVER_FORGET_S]

    def _run(self) -> None:
        import pylsl

        while True:
            if time.monotonic() - self._wanted_at > FINDER_IDLE_S:
                self._wake.clear()
                self._wake.wait()
            started = time.monotonic()
            found = pylsl.resolve_bypred(self.query, 1, FINDER_QUERY_S)
            now = time.monotonic()
            with self._lock:
                self._seen.update((info.uid(), (info, now)) for info in found)
                self._seen = {uid: seen for uid, seen in self._seen.items() if now - seen[1] <= RESOLVER_FORGET_S}
            time.sleep(max(0.0, FINDER_PACE_S - (now - started)))


class LslInput:
    """An LSL inlet that is re-resolved whenever its stream is lost.

    Parameters
    ----------
    stream_type : str
    name : str or None
        The stream's name (any of the type if None).
    widths : tuple of int
        Channel counts accepted (2 or 3 for work; ``3 J`` for MoCap); a stream of another width or
        with string channels is refused with one line on ``log`` and the server waits for another.
    log : text stream, optional
    """

    def __init__(self, stream_type: str, name: str | None, widths: Sequence[int] = (2, 3),
                 log: IO[str] | None = None) -> None:
        self.stream_type, self.name = stream_type, name
        self.widths = tuple(widths)
        self.log = log if log is not None else sys.stderr
        self._inlet: Any = None
        self._refused: set[str] = set()
        self._gone: set[str] = set()  # streams lost: the resolver may list them a while longer
        self._uid, self._created_at = "", 0.0
        self._finder: StreamFinder | None = None
        self._last_data = self._last_probe = 0.0
        self.srate_hz = 0.0
        self.channels = 0

    def query(self) -> str:
        """The LSL predicate that finds the input (names quoted safely)."""
        return f"type={xpath_literal(self.stream_type)}" + (f" and name={xpath_literal(self.name)}"
                                                             if self.name is not None else "")

    def _acceptable(self, info: Any) -> bool:
        """True for a stream of an accepted width with numeric channels; else one line, once per stream."""
        width, numeric = info.channel_count(), info.channel_format() != _LSL_STRING_FORMAT
        if width in self.widths and numeric:
            return True
        key = info.uid()
        if key not in self._refused:
            self._refused.add(key)
            wanted = " or ".join(map(str, self.widths))
            found = f"{width} channels" if numeric else f"{width} string channels"
            print(f"serve: input {info.name()!r} ({self.stream_type}): expected {wanted} numeric channels, found "
                  f"{found}; ignored, waiting for another", file=self.log, flush=True)
        return False

    def _connect(self, stats: ServeStats) -> bool:
        import pylsl

        listed = self._listed()
        found = [info for info in listed
                 if info.uid() not in self._gone and self._acceptable(info)]  # not the stream just lost
        if not found:
            time.sleep(REFUSED_WAIT_S)  # the resolver answers at once: do not spin
            return False
        from pylsl.util import LostError, TimeoutError as LslTimeout

        newest = max(found, key=lambda info: info.created_at())  # not a stream that just went
        holder = [pylsl.StreamInlet(newest, max_buflen=10, recover=False)]
        try:
            holder[0].open_stream(0.5)
        except (LostError, LslTimeout):  # a stream that just went (the resolver still lists it)
            _discard(holder)
            return False
        inlet = holder.pop()
        self._inlet = inlet
        self._uid, self._created_at = newest.uid(), newest.created_at()
        self._last_data = self._last_probe = time.monotonic()
        self.srate_hz = newest.nominal_srate()
        self.channels = newest.channel_count()
        stats.connects += 1
        return True

    def _replaced(self) -> bool:
        """True if, after a silence, the input's query finds another stream and not this one (the source
        restarted): LSL may take seconds to report the old inlet lost, so the server switches now."""
        now = time.monotonic()
        quiet_s = max(SILENCE_PROBE_S, 3.0 / self.srate_hz if self.srate_hz > 0 else SILENCE_PROBE_S)
        if now - self._last_data < quiet_s or now - self._last_probe < REFUSED_WAIT_S:
            return False
        self._last_probe = now
        return any(info.uid() != self._uid and info.created_at() > self._created_at
                   and info.uid() not in self._gone and self._acceptable(info) for info in self._listed())

    def _listed(self) -> list[Any]:
        """The streams the query finds now, from the background :class:`StreamFinder` (never blocks)."""
        if self._finder is None:
            self._finder = StreamFinder(self.query())
        return self._finder.listed()

    def pull(self, stats: ServeStats) -> tuple[list, list] | None:
        """Samples and time stamps available now (waiting up to 0.1 s); None while disconnected."""
        from pylsl.util import LostError

        if self._inlet is None and not self._connect(stats):
            return None
        try:
            first, stamp = self._inlet.pull_sample(timeout=0.1)
            if first is None:
                if self._replaced():
                    raise LostError("replaced by a newer stream")
                return [], []
            more, stamps = self._inlet.pull_chunk(timeout=0.0)
            self._last_data = time.monotonic()
            return [first, *more], [stamp, *stamps]
        except LostError:
            holder, self._inlet = [self._inlet], None
            _discard(holder)
            self._gone.add(self._uid)
            stats.losses += 1
            return None


class OscInput:
    """``/effortface/work w p [dt]`` messages on a UDP port, read from a plain socket.

    Every datagram is parsed here, so one that does not parse (garbage, a truncated packet, a deep
    bundle) or carries another address is counted in :attr:`ServeStats.bad`, never raised; at most
    :data:`MAX_DATAGRAMS_PER_PULL` are read per pull.

    Raises
    ------
    UserError
        If the port cannot be bound (in use, out of range, not permitted).
    """

    def __init__(self, port: int, host: str = "127.0.0.1") -> None:
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self._sock.bind((host, port))
        except (OSError, OverflowError) as exc:
            self._sock.close()
            why = getattr(exc, "strerror", None) or str(exc)
            raise UserError(f"--osc-in-port {port}: expected a free UDP port, found {why} (another serve?)") from None
        self.port = self._sock.getsockname()[1]
        self.srate_hz = 0.0

    def pull(self, stats: ServeStats) -> tuple[list, list]:
        """Messages received now (waiting up to 0.1 s for the first)."""
        values: list[Any] = []
        stamps: list[float] = []
        timeout = 0.1
        for _ in range(MAX_DATAGRAMS_PER_PULL):
            ready, _, _ = select.select([self._sock], [], [], timeout)
            if not ready:
                break
            try:
                data = self._sock.recv(65536)
            except OSError:  # e.g. an ICMP error reported on the socket
                break
            now = time.monotonic()
            for params in parse_work_datagram(data, stats):
                values.append(params)
                stamps.append(now)
            timeout = 0.0
        return values, stamps

    def close(self) -> None:
        self._sock.close()


def parse_work_datagram(data: bytes, stats: ServeStats) -> list[list[Any]]:
    """The parameters of every ``/effortface/work`` message in one OSC datagram (message or bundle).

    A datagram that does not parse, and every message with another address, is counted in
    ``stats.bad``; the parameters themselves are checked later (:func:`check_sample`).
    """
    from pythonosc.osc_packet import OscPacket

    try:
        messages = [timed.message for timed in OscPacket(data).messages]
    except Exception:  # noqa: BLE001 - python-osc raises several types (ParseError, struct, index,
        stats.bad += 1  # recursion) on hostile bytes; a datagram never stops the server
        return []
    out = []
    for message in messages:
        if message.address == OSC_WORK_ADDRESS:
            out.append(list(message.params))
        else:
            stats.bad += 1
    return out


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
            checked = check_sample(sample, processor.n_joints)
            if checked is None or not math.isfinite(stamp):
                stats.bad += 1
                continue
            dt_s = (checked[2] if len(checked) > 2 and not processor.n_joints else
                    (stamp - last_stamp if last_stamp is not None else 1.0 / processor.fps))
            last_stamp = stamp
            row = processor.step(checked, dt_s)
            stats.received += 1
            if row is None:
                stats.bad += 1
                continue
            outputs.send(row, stamp)
            stats.sent += 1
            if on_row is not None:
                on_row(row)
        now = time.monotonic()
        if now >= next_report:
            span = now - next_report + report_s
            print(f"serve: in {(stats.received - last_counts[0]) / span:.1f} Hz, out "
                  f"{(stats.sent - last_counts[1]) / span:.1f} Hz, connects {stats.connects}, "
                  f"losses {stats.losses}, bad {stats.bad}", file=log, flush=True)
            next_report, last_counts = now + report_s, (stats.received, stats.sent)
    return stats
