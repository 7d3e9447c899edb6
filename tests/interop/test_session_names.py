"""Issue 37: two sessions of one participant started in the same second never clash.

Two ``import xdf`` (or two captures) of one participant in one second wanted the same folder: the
second was a bare FileExistsError traceback. Now the second gets a suffix (``_2``, or ``-2`` after a
label), ``session.json`` records the id it wanted, and a stderr line says so; nothing is replaced.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from effortface.cli import main
from effortface.core.session.folder import (ID_TAKEN_KEY, MAX_SESSION_SUFFIX, free_session_id,
                                             parse_session_id, read_session)
from effortface.core.errors import UserError
from effortface.interop import xdf_import

from .xdf_writer import XdfStream, write_xdf

T0 = 5000.0

def _xdf(tmp_path: Path, hr: float) -> Path:
    stream = XdfStream("Polar", "HeartRate", [("hr_bpm", "bpm"), ("rr_ms", "ms")], [T0 + k for k in range(20)],
                       [[hr, 750.0]] * 20)
    return write_xdf(tmp_path / f"r{hr:g}.xdf", [stream])


@pytest.mark.parametrize("label", [None, "bike"])
def test_two_imports_in_the_same_second_get_a_stated_suffix(tmp_path, freeze_now, capsys, label) -> None:
    freeze_now(xdf_import)
    out = tmp_path / "lab"
    extra = ["--label", label] if label else []
    first, second, third = (_xdf(tmp_path, hr) for hr in (80, 90, 100))
    for xdf in (first, second, third):
        assert main(["import", "xdf", str(xdf), "--out", str(out), "--participant", "P01", *extra]) == 0
    err = capsys.readouterr().err.splitlines()
    base = "P01_20260302-101507" + (f"_{label}" if label else "")
    names = [base, f"{base}-2" if label else f"{base}_2", f"{base}-3" if label else f"{base}_3"]
    assert sorted(p.name for p in out.iterdir()) == sorted(names)
    assert err == [f"effortface import: note: a session folder {base} exists already (a session of P01 started "
                   f"the same second): this one is {name}" for name in names[1:]]
    for name, hr in zip(names, (80, 90, 100)):
        session = read_session(out / name)
        assert session.info.session_id == name and parse_session_id(name)[0] == "P01"
        with open(out / name / "heart_rate.csv", newline="") as fh:
            assert {round(float(r["hr_bpm"])) for r in csv.DictReader(fh)} == {hr}  # nothing replaced
    assert ID_TAKEN_KEY not in json.loads((out / base / "session.json").read_text())
    assert json.loads((out / names[1] / "session.json").read_text())[ID_TAKEN_KEY] == base
    assert not [p for p in out.iterdir() if p.name.startswith(".")]


def test_every_suffix_taken_is_one_line(tmp_path) -> None:
    base = "P01_20260302-101507"
    for name in [base, *(f"{base}_{n}" for n in range(2, MAX_SESSION_SUFFIX + 1))]:
        (tmp_path / name).mkdir()
    with pytest.raises(UserError, match=rf"{base}: expected a free session folder name, found it and its "
                                        rf"suffixes up to {MAX_SESSION_SUFFIX} taken"):
        free_session_id(tmp_path, base)


@pytest.mark.parametrize("fmt", ["xdf", "hr"])
def test_a_sigterm_during_an_import_leaves_no_staging_folder(tmp_path, monkeypatch, capsys, fmt) -> None:
    """SIGTERM (sent to this process) while the session's heart rate is being written: exit 143, one
    line, and neither the staging folder ``.import-*.tmp`` nor a session folder is left."""
    import os
    import signal
    import time

    from effortface.core.session import folder as session_folder

    real = session_folder.HrWriter.write

    def write_then_stop(self, *args, **kwargs):
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(0.05)  # the handler runs here
        return real(self, *args, **kwargs)

    monkeypatch.setattr(session_folder.HrWriter, "write", write_then_stop)
    out = tmp_path / "lab"
    if fmt == "xdf":
        args = ["import", "xdf", str(_xdf(tmp_path, 80)), "--out", str(out), "--participant", "P01"]
    else:
        csv_path = tmp_path / "hr.csv"
        csv_path.write_text("time,hr\n" + "".join(f"2026-03-02T10:15:{k:02d},{80 + k % 5}\n" for k in range(30)))
        args = ["import", "hr", str(csv_path), "--out", str(out), "--participant", "P01", "--sex", "female",
                "--age", "30", "--height", "1.7", "--mass", "60", "--training-level", "5"]
    assert main(args) == 143
    assert capsys.readouterr().err.splitlines() == [
        "effortface import: stopped by SIGTERM; what it had not finished was not written"]
    assert not out.exists() or [p.name for p in out.iterdir() if p.name != "participants.tsv"] == []
