"""Helpers shared by the capture I/O tests: real HxM excerpts as .serlog, numbered test videos,
and running ``effortface replay`` / ``capture`` as subprocesses."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from effortface.capture_tool.captures import read_timed_capture
from effortface.capture_tool.protocols import HrSample, get_decoder
from effortface.capture_tool.serlog import SerlogWriter

HXM_DAT = Path("serial/zephyr-bt/120-second-bt-stream-hxm.dat")
#: the demographics a capture requires (options of ``effortface capture``)
BODY = ("--sex", "female", "--age", "30", "--height", "1.68", "--mass", "60", "--training-level", "4")
BITS = 12  # frame numbers up to 4095, one 10 x 10 block per bit along the top of the image
BLOCK = 10


def hxm_chunks(shared_data: Path, start_s: float = 0.0, stop_s: float | None = None) -> list[tuple[float, bytes]]:
    """The real HxM capture's timed reads within [start_s, stop_s), times relative to start_s."""
    chunks = read_timed_capture(shared_data / HXM_DAT)
    return [(t - start_s, d) for t, d in chunks if t >= start_s and (stop_s is None or t < stop_s)]


def write_serlog(path: Path, chunks: list[tuple[float, bytes]], protocol: str = "hxm") -> Path:
    """Write timed chunks as a .serlog (what a recording of them would have logged)."""
    with SerlogWriter(path, {"protocol": protocol, "device": protocol}) as w:
        for t, d in chunks:
            w.write(t, d)
    return path


def decode(chunks: list[tuple[float, bytes]], protocol: str = "hxm") -> list[HrSample]:
    """Decode timed chunks in-process: the reference a recording must equal."""
    return decode_parts([chunks], protocol)


def decode_parts(parts: list[list[tuple[float, bytes]]], protocol: str = "hxm") -> list[HrSample]:
    """Decode streams cut by unplugs: one decoder, its partial frame dropped at each cut."""
    dec = get_decoder(protocol)
    out: list[HrSample] = []
    for chunks in parts:
        for t, d in chunks:
            out += dec.feed(d, t)
        out += dec.finish()
    return out


def content(samples: list[HrSample]) -> list[tuple]:
    """What a heart-rate row says, without its arrival time (which depends on the replay)."""
    return [(s.hr_bpm, s.rr_ms, s.beat_count, s.device, s.valid) for s in samples]


def make_numbered_video(path: Path, n_frames: int, fps: float = 30.0, size: tuple[int, int] = (160, 120)) -> Path:
    """Write an MJPG AVI whose frame k shows k in binary blocks (and as text)."""
    import cv2

    w, h = size
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, (w, h))
    for k in range(n_frames):
        img = np.full((h, w, 3), 60, np.uint8)
        for bit in range(BITS):
            if k >> bit & 1:
                img[0:BLOCK, bit * BLOCK:(bit + 1) * BLOCK] = 255
            else:
                img[0:BLOCK, bit * BLOCK:(bit + 1) * BLOCK] = 0
        cv2.putText(img, str(k), (5, h - 20), cv2.FONT_HERSHEY_SIMPLEX, 1.0, (255, 255, 255), 2)
        writer.write(img)
    writer.release()
    return path


def frame_number(img: np.ndarray) -> int:
    """Read back the number drawn by :func:`make_numbered_video`."""
    gray = img.mean(axis=2)
    n = 0
    for bit in range(BITS):
        if gray[2:BLOCK - 2, bit * BLOCK + 2:(bit + 1) * BLOCK - 2].mean() > 127:
            n |= 1 << bit
    return n


def effortface(*args: str) -> list[str]:
    """The command line to run ``effortface`` with this interpreter."""
    return [sys.executable, "-m", "effortface", *map(str, args)]


def start_replay(log: Path, *extra: str) -> tuple[subprocess.Popen, str]:
    """Start ``effortface replay LOG ...``; return the process and the pty path it printed."""
    proc = subprocess.Popen(effortface("replay", log, *extra), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env={**os.environ, "PYTHONUNBUFFERED": "1"})
    line = proc.stdout.readline().strip()
    assert line.startswith("/dev/"), (line, proc.stderr.read() if proc.poll() is not None else "")
    return proc, line
