"""Issue 29: a damaged ``.serlog`` decodes all but the damaged record, says so on stderr and exits 1.

The log is the real HxM strap capture (tests/data/serial) written as ``capture`` writes it; one record
in the middle is damaged the ways a flipped bit or a torn disk block does.
"""

from __future__ import annotations

import math
import struct
import subprocess
import sys
from pathlib import Path

import pytest

from effortface.capture_tool.captures import read_timed_capture
from effortface.capture_tool.recorder import decode_serlog
from effortface.capture_tool.serlog import MAGIC, SerlogWriter, read_serlog
from effortface.cli import main

HXM = "serial/zephyr-bt/120-second-bt-stream-hxm.dat"
_REC = struct.Struct("<BdI")


def _log(shared_data: Path, tmp_path: Path) -> tuple[Path, list[int]]:
    """The HxM capture as a .serlog, and the byte offset of every record."""
    log = tmp_path / "hxm.serlog"
    with SerlogWriter(log, {"device": "hxm", "protocol": "hxm"}) as writer:
        for t_s, data in read_timed_capture(shared_data / HXM):
            writer.write(t_s, data)
    blob = log.read_bytes()
    pos, offsets = blob.index(b"\n", len(MAGIC)) + 1, []
    while pos < len(blob):
        offsets.append(pos)
        pos += _REC.size + _REC.unpack_from(blob, pos)[2]
    return log, offsets


def _damage(blob: bytearray, at: int, how: str) -> None:
    kind, t_s, n = _REC.unpack_from(blob, at)
    if how == "kind":
        blob[at] = 0x7F
    elif how == "longer":
        struct.pack_into("<I", blob, at + 9, n + 5)
    elif how == "shorter":
        struct.pack_into("<I", blob, at + 9, max(0, n - 3))
    elif how == "nan time":
        struct.pack_into("<d", blob, at + 1, math.nan)
    elif how == "huge length":
        struct.pack_into("<I", blob, at + 9, 0x00FFFFF0)


@pytest.mark.parametrize("how", ["kind", "longer", "shorter", "nan time", "huge length"])
def test_one_damaged_record_costs_only_itself(shared_data, tmp_path, capsys, how) -> None:
    log, offsets = _log(shared_data, tmp_path)
    assert main(["decode", str(log)]) == 0
    whole = capsys.readouterr().out.splitlines()
    blob = bytearray(log.read_bytes())
    at = offsets[len(offsets) // 2]
    _damage(blob, at, how)
    log.write_bytes(bytes(blob))
    assert main(["decode", str(log)]) == 1
    got = capsys.readouterr()
    rows = got.out.splitlines()
    assert len(whole) - 2 <= len(rows) < len(whole)  # at most the frames the damaged read held are lost
    beats = {(r.split(",")[1], r.split(",")[3]) for r in rows}  # heart rate and beat count of each row
    assert beats <= {(r.split(",")[1], r.split(",")[3]) for r in whole}  # nothing invented
    warning = [line for line in got.err.splitlines() if line.startswith("warning:")]
    assert warning == [f"warning: {log}: skipped {read_serlog(log).skipped_bytes} damaged bytes in 1 place "
                       f"(first at byte {at})"], got.err
    assert read_serlog(log).truncated_bytes == 0


def test_damage_in_several_places_and_a_torn_tail_are_told_apart(shared_data, tmp_path) -> None:
    log, offsets = _log(shared_data, tmp_path)
    n_records = len(read_serlog(log).records)
    blob = bytearray(log.read_bytes())
    for k in (10, 50, 90):
        blob[offsets[k]] = 0xFF
    log.write_bytes(bytes(blob) + _REC.pack(0, 130.0, 40) + b"torn")  # a crash cut the last record
    read = read_serlog(log)
    assert (read.skipped_places, read.first_skip_at, len(read.records)) == (3, offsets[10], n_records - 3)
    assert read.truncated_bytes == _REC.size + 4
    notes: list[str] = []
    decode_serlog(log, notes)  # recover says what it skipped
    assert any("skipped" in note and "damaged bytes in 3 place(s)" in note for note in notes), notes


def test_an_intact_log_is_exit_0_with_no_warning_in_a_subprocess(shared_data, tmp_path) -> None:
    log, _ = _log(shared_data, tmp_path)
    proc = subprocess.run([sys.executable, "-m", "effortface", "decode", str(log)], capture_output=True, text=True,
                          timeout=60)
    assert proc.returncode == 0 and "warning" not in proc.stderr
    blob = bytearray(log.read_bytes())
    blob[len(blob) // 2:len(blob) // 2 + 40] = b"\xff" * 40  # a burst of garbage inside records
    log.write_bytes(bytes(blob))
    proc = subprocess.run([sys.executable, "-m", "effortface", "decode", str(log)], capture_output=True, text=True,
                          timeout=60)
    assert proc.returncode == 1 and "Traceback" not in proc.stderr
    assert proc.stderr.splitlines()[-1].startswith(f"warning: {log}: skipped ")
