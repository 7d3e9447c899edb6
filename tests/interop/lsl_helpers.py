"""Real pylsl outlets for the interop tests: a paced EffortWork sender and inlet helpers."""

from __future__ import annotations

import threading
import time
import uuid

import pylsl


def unique(prefix: str) -> str:
    """A stream name no other test (or engineer on this machine) uses."""
    return f"{prefix}-{uuid.uuid4().hex[:10]}"


class WorkSender:
    """An LSL ``EffortWork`` outlet pushing (w, p) at ``rate_hz`` from a thread until closed."""

    def __init__(self, name: str, rate_hz: float = 120.0, w_per_kg: float = 12.0) -> None:
        info = pylsl.StreamInfo(name, "EffortWork", 2, rate_hz, "float32", name)
        self.outlet = pylsl.StreamOutlet(info)
        self.rate_hz, self.w = rate_hz, w_per_kg
        self.stamps: list[float] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        period = 1.0 / self.rate_hz
        next_t = time.perf_counter()
        while not self._stop.is_set():
            stamp = pylsl.local_clock()
            self.outlet.push_sample([self.w, self.w * 1.5], stamp)
            self.stamps.append(stamp)
            next_t += period
            self._stop.wait(max(0.0, next_t - time.perf_counter()))

    def close(self) -> None:
        """Stop pushing and destroy the outlet (the stream disappears)."""
        self._stop.set()
        self._thread.join(5)
        del self.outlet


def pull_for(inlet: pylsl.StreamInlet, seconds: float) -> tuple[list, list]:
    """Everything an inlet receives during ``seconds``."""
    values, stamps = [], []
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        chunk, ts = inlet.pull_chunk(timeout=0.1)
        values += chunk
        stamps += ts
    return values, stamps
