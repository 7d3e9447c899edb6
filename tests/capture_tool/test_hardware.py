"""Real-strap tests: run only when asked, e.g. ``pytest --hr-port=/dev/ttyUSB0 --hr-protocol=ant``.

Everything else in the suite replays real recorded bytes through pseudo-terminals; these check the
same code path on a strap worn by a person (bleak's pattern: hardware tests skip with a reason that
says how to enable them).
"""

from __future__ import annotations

import queue
import time

from effortface.capture_tool.protocols import HrSample, get_decoder
from effortface.capture_tool.recorder import device_startup_frames
from effortface.capture_tool.serial_link import SerialLink
from effortface.capture_tool.serlog import read_serlog


def test_a_worn_strap_gives_plausible_heart_rate(hr_port, hr_protocol, tmp_path):
    out: queue.Queue = queue.Queue()
    t0 = time.monotonic()
    link = SerialLink(hr_port, get_decoder(hr_protocol), out, lambda: time.monotonic() - t0,
                      device="strap", startup_frames=device_startup_frames(hr_protocol, hr_port))
    link.start(tmp_path / "strap.serlog")
    time.sleep(15.0)
    link.stop()
    items = []
    while not out.empty():
        items.append(out.get())
    samples = [s for kind, s in items if kind == "hr" and isinstance(s, HrSample) and s.valid]
    assert samples, f"no valid heart rate in 15 s from {hr_port} ({hr_protocol}); is the strap worn?"
    assert all(30 <= s.hr_bpm <= 220 for s in samples)
    assert read_serlog(tmp_path / "strap.serlog").data_bytes(), "raw bytes were not logged"
