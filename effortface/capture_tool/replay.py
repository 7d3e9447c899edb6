"""Simulated serial ports: replay a recorded strap through a pseudo-terminal or a ``replay://`` URL.

:func:`open_pty_replay` opens a pseudo-terminal in raw mode; any program (``effortface capture``,
a terminal program, pyserial) opens its slave path like a USB serial port, and the recorded bytes
arrive with their recorded timing (or ``speed`` times faster). Closing the master end is what
pulling the stick out looks like to the reader: its next read fails with ``EIO``. A stable symlink
re-pointed at a new pseudo-terminal is a fair replug (the reader re-opens the same path).

Sources: a ``.serlog`` (data records; link events are not replayed), a ``.pcap``, or a raw capture
with its timing file, all read by :mod:`effortface.capture_tool.captures`.
"""

from __future__ import annotations

import dataclasses
import fcntl
import os
import select
import struct
import termios
import threading
import time
import tty
from pathlib import Path

from effortface.core.errors import UserError
from effortface.capture_tool.captures import read_timed_capture

#: seconds a reader that closed the port in mid-play has to open it again before the replay ends
READER_RETURN_S = 2.0


@dataclasses.dataclass(frozen=True)
class TimedChunk:
    """Bytes ``data`` that arrived ``t_s`` seconds after the first chunk of the recording."""

    t_s: float
    data: bytes


def load_timed_chunks(path: str | os.PathLike) -> list[TimedChunk]:
    """Load a recording as timed chunks, the first at ``t_s = 0``.

    Parameters
    ----------
    path : path-like
        A ``.serlog``, a ``.pcap``, or a raw capture with its timing file
        (:func:`effortface.capture_tool.captures.read_timed_capture`).

    Raises
    ------
    UserError
        If the file is missing, unreadable, or not a capture format.
    """
    path = Path(path)
    if path.is_dir():
        raise UserError(f"{path}: expected a .serlog or raw capture file to replay, found a folder")
    chunks = read_timed_capture(path)
    t0_s = chunks[0][0] if chunks else 0.0  # a replay starts at once, whatever the session time
    return [TimedChunk(t_s - t0_s, bytes(data)) for t_s, data in chunks]


class PtyReplay:
    """A pseudo-terminal that plays timed chunks into its master end.

    Parameters
    ----------
    chunks : list of TimedChunk
        What to play.
    speed : float
        Time scale: 10 plays ten times faster than recorded.
    unplug_after_s : float, optional
        Close the port after this many seconds *of the recording* (``unplug_after_s / speed`` of
        wall time), as if the stick was pulled out.

    Attributes
    ----------
    path : str
        The slave path to open (``/dev/pts/N``).
    write_times : list of tuple
        ``(time.monotonic(), chunk index)`` of each write, for latency measurements.
    """

    def __init__(self, chunks: list[TimedChunk], speed: float = 1.0, unplug_after_s: float | None = None) -> None:
        if not speed > 0:
            raise UserError(f"--speed: expected a number above 0, found {speed!r}")
        self.chunks = chunks
        self.speed = float(speed)
        self.unplug_after_s = unplug_after_s
        self._master, slave = os.openpty()
        tty.setraw(slave)
        self.path: str = os.ttyname(slave)
        os.close(slave)  # the master now sees POLLHUP until a reader opens the slave
        self._stop = threading.Event()
        #: True when :meth:`play` ended early because the reader closed the port for good
        self.reader_left = False
        self.bytes_written = 0
        self.write_times: list[tuple[float, int]] = []

    def _hangup(self, timeout_s: float) -> bool:
        """True if no reader has the slave open (POLLHUP on the master) within ``timeout_s``."""
        p = select.poll()
        p.register(self._master, select.POLLHUP)
        return bool(p.poll(max(0, int(timeout_s * 1000))))

    def wait_for_reader(self, timeout_s: float = 30.0) -> bool:
        """Block until some program opens the slave; False on timeout or :meth:`stop`."""
        deadline = time.monotonic() + timeout_s
        while not self._stop.is_set() and time.monotonic() < deadline:
            if not self._hangup(0):
                return True
            time.sleep(0.01)
        return False

    def play(self) -> int:
        """Write every chunk at its time (stopping at ``unplug_after_s``); return bytes written."""
        t0 = time.monotonic()
        for i, chunk in enumerate(self.chunks):
            if self.unplug_after_s is not None and chunk.t_s > self.unplug_after_s:
                break
            if self._stop.wait(max(0.0, t0 + chunk.t_s / self.speed - time.monotonic())):
                break
            if not self._write_all(chunk.data):
                self.reader_left = True  # the reader closed the port and did not come back: it is done
                break
            self.write_times.append((time.monotonic(), i))
        if self.unplug_after_s is not None and not self._stop.is_set():
            self._stop.wait(max(0.0, t0 + self.unplug_after_s / self.speed - time.monotonic()))
            self.wait_drained()
            self.close()
        return self.bytes_written

    def pending_bytes(self) -> int:
        """Bytes written but not yet read by the reader (the slave's input queue)."""
        try:
            fd = os.open(self.path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
        except OSError:
            return 0
        try:
            return struct.unpack("i", fcntl.ioctl(fd, termios.FIONREAD, b"\0" * 4))[0]
        finally:
            os.close(fd)

    def wait_drained(self, timeout_s: float = 2.0) -> bool:
        """Wait until the reader has read every byte written; False on timeout.

        Closing a pseudo-terminal's master discards what the slave has not read yet, so the
        simulated unplug waits for this first: the bytes sent before the pull all arrive.
        """
        deadline = time.monotonic() + timeout_s
        while self._master >= 0 and self.pending_bytes() > 0:
            if time.monotonic() >= deadline:
                return False
            time.sleep(0.005)
        return True

    def _write_all(self, data: bytes) -> bool:
        """Write all of ``data`` to the master (the tty may accept it in pieces); False when the reader
        closed the port and no program opened it again within :data:`READER_RETURN_S` (a write with
        no reader would block for ever once the tty's buffer is full), or on :meth:`stop`."""
        view = memoryview(data)
        while view:
            if not self._writable():
                return False
            n = os.write(self._master, view)
            self.bytes_written += n
            view = view[n:]
        return True

    def _writable(self) -> bool:
        """Wait until the master takes bytes; False on :meth:`stop` or a reader gone for good."""
        p = select.poll()
        p.register(self._master, select.POLLOUT | select.POLLHUP)
        while not self._stop.is_set():
            events = dict(p.poll(50)).get(self._master, 0)
            if events & select.POLLHUP and not self.wait_for_reader(READER_RETURN_S):
                return False
            if events & select.POLLOUT and not events & select.POLLHUP:
                return True
        return False

    def hold(self, timeout_s: float | None = None) -> None:
        """Keep the (now silent) port open until the reader closes it, :meth:`stop`, or timeout."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while self._master >= 0 and not self._stop.is_set():
            if deadline is not None and time.monotonic() >= deadline:
                return
            if self._hangup(0.05):
                return

    def stop(self) -> None:
        """Ask :meth:`play`, :meth:`hold` and :meth:`wait_for_reader` to return early."""
        self._stop.set()

    @property
    def stopped(self) -> bool:
        """Whether :meth:`stop` was called (a signal, not a timeout, ended the wait)."""
        return self._stop.is_set()

    def close(self) -> None:
        """Close the master end: the reader sees the device vanish (idempotent)."""
        if self._master >= 0:
            os.close(self._master)
            self._master = -1

    def __enter__(self) -> PtyReplay:
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()
        self.close()


def open_pty_replay(log: str | os.PathLike, speed: float = 1.0, unplug_after_s: float | None = None) -> PtyReplay:
    """Open a raw-mode pseudo-terminal that will replay ``log``.

    Parameters
    ----------
    log : path-like
        A ``.serlog`` or a raw capture with its timing file.
    speed : float
        Replay speed factor (1 = recorded timing).
    unplug_after_s : float, optional
        Seconds of the recording after which the port is closed.

    Returns
    -------
    PtyReplay
        Not playing yet: open ``replay.path``, then call ``replay.play()`` (or :func:`start_replay_thread`).
    """
    return PtyReplay(load_timed_chunks(log), speed=speed, unplug_after_s=unplug_after_s)


def start_replay_thread(replay: PtyReplay, wait_for_reader: bool = True) -> threading.Thread:
    """Play ``replay`` in a daemon thread (after a reader opens it, if asked); return the thread."""

    def _run() -> None:
        if not wait_for_reader or replay.wait_for_reader():
            replay.play()

    thread = threading.Thread(target=_run, name="pty-replay", daemon=True)
    thread.start()
    return thread
