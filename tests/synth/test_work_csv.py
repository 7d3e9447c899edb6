"""Issue 37: one checked work.csv reader (file, line, field) used by every command that reads the file:
``export bids`` (which wrote a negative sampling frequency for times going back and gave a
UnicodeDecodeError traceback for a non-UTF-8 byte), ``train`` and the reader itself."""

from __future__ import annotations

import math
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from effortface.synth.work import WorkError, read_work_csv, write_work
from effortface.train.dataset import DatasetError, session_table

ROOT = Path(__file__).resolve().parents[2]
SESSION = ROOT / "sample_sessions" / "P01_20260112-093000_cardio"
GOOD = "t_s,w_per_kg,p_per_kg,source\n0,0.1000,0.1000,log:rest\n1,,,\n2,4.2,4.0,log:bike\n"

#: hostile work.csv texts (bytes) -> the one line expected (after the file name)
HOSTILE = {
    "non_utf8": (b"t_s,w_per_kg,p_per_kg\n0,0.1\xff,0.1\n", r"expected UTF-8 text, found byte 0xff"),
    "time_back": (b"t_s,w_per_kg,p_per_kg\n0,1,1\n2,1,1\n1,1,1\n",
                  r"line 4: t_s: expected times increasing \(rows sorted by time\), found 1 after 2"),
    "time_repeated": (b"t_s,w_per_kg,p_per_kg\n0,1,1\n0,1,1\n", r"line 3: t_s: expected times increasing"),
    "time_negative": (b"t_s,w_per_kg,p_per_kg\n-1,1,1\n", r"line 2: t_s: expected a number from 0 to 1e\+06 s, found -1"),
    "time_nan": (b"t_s,w_per_kg,p_per_kg\nnan,1,1\n", r"line 2: t_s: expected a number from 0 to 1e\+06 s, found nan"),
    "time_empty": (b"t_s,w_per_kg,p_per_kg\n,1,1\n", r"line 2: t_s: expected a number, found ''"),
    "work_inf": (b"t_s,w_per_kg,p_per_kg\n0,inf,1\n", r"line 2: w_per_kg: expected a number from -1000 to 1000 W/kg"),
    "power_huge": (b"t_s,w_per_kg,p_per_kg\n0,1,1e300\n", r"line 2: p_per_kg: expected a number from -1000 to 1000 W/kg"),
    "text": (b"t_s,w_per_kg,p_per_kg\n0,abc,1\n", r"line 2: w_per_kg: expected a number, found 'abc'"),
    "short_row": (b"t_s,w_per_kg,p_per_kg\n0,1\n", r"line 2: expected the fields t_s,w_per_kg,p_per_kg, found a row of 2 fields"),
    "no_column": (b"t_s,w_per_kg\n0,1\n", r"expected a header with columns t_s,w_per_kg,p_per_kg, found 't_s,w_per_kg'"),
    "empty": (b"", r"expected a header with columns t_s,w_per_kg,p_per_kg, found 'an empty file'"),
    "no_rows": (b"t_s,w_per_kg,p_per_kg\n", r"expected rows of t_s,w_per_kg,p_per_kg, found none"),
    "field_over_csv_limit": (b"t_s,w_per_kg,p_per_kg\n0,1,\"" + b"9" * 200_000 + b"\"\n",
                             r"expected CSV fields of at most 131072 characters, found a longer one"),
}


def _lab(tmp_path: Path, text: bytes) -> Path:
    """A one-session lab (no video, no serial log) whose work.csv is ``text``."""
    dst = tmp_path / "lab" / SESSION.name
    shutil.copytree(SESSION, dst, ignore=shutil.ignore_patterns("video.avi", "serial"))
    (dst / "work.csv").write_bytes(text)
    return dst


def test_the_written_and_hand_made_forms_read(tmp_path):
    path = tmp_path / "work.csv"
    path.write_text(GOOD)
    table = read_work_csv(path)
    assert table.t_s.tolist() == [0, 1, 2] and table.source == ["log:rest", "", "log:bike"]
    assert math.isnan(table.w_per_kg[1]) and table.p_per_kg[2] == 4.0
    path.write_bytes(b"\xef\xbb\xbft_s ,w_per_kg,p_per_kg\r\n0.5,nan,n/a\r\n1.7,1,2\r\n")   # Excel: BOM, CRLF
    table = read_work_csv(path)
    assert table.t_s.tolist() == [0.5, 1.7] and table.source == ["", ""] and np.isnan(table.w_per_kg[0])
    folder = tmp_path / "session"
    shutil.copytree(SESSION, folder, ignore=shutil.ignore_patterns("video.avi", "serial"))
    _, derived = write_work(folder)
    again = read_work_csv(folder / "work.csv")
    np.testing.assert_allclose(again.w_per_kg, derived.w_per_kg, atol=5e-5, equal_nan=True)
    assert again.source == derived.source


@pytest.mark.parametrize("case", HOSTILE, ids=list(HOSTILE))
def test_a_hostile_work_csv_is_one_line_naming_file_line_and_field(tmp_path, case):
    text, message = HOSTILE[case]
    path = tmp_path / "work.csv"
    path.write_bytes(text)
    with pytest.raises(WorkError) as info:
        read_work_csv(path)
    assert str(info.value).startswith(f"{path}: ") and "\n" not in str(info.value)
    assert re.search(message, str(info.value)), str(info.value)


def test_a_folder_is_not_a_work_csv(tmp_path):
    (tmp_path / "work.csv").mkdir()
    with pytest.raises(WorkError, match=r"work\.csv: expected a work CSV file .*found a folder"):
        read_work_csv(tmp_path / "work.csv")


@pytest.mark.parametrize("case", ["non_utf8", "time_back"])
def test_export_bids_and_train_refuse_the_same_file_the_same_way(tmp_path, case):
    """Before: export bids wrote SamplingFrequency -1.0 for times going back (exit 0) and gave a
    UnicodeDecodeError traceback for a non-UTF-8 byte; train read the file with its own reader."""
    text, message = HOSTILE[case]
    session = _lab(tmp_path, text)
    out = tmp_path / "ds"
    done = subprocess.run([sys.executable, "-m", "effortface", "export", "bids", session.parent, "--out", out],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 2 and "Traceback" not in done.stderr, done.stderr
    (line,) = done.stderr.strip().splitlines()
    assert line.startswith(f"effortface export: error: {session / 'work.csv'}: ") and re.search(message, line), line
    assert not out.exists() and [p.name for p in tmp_path.iterdir()] == ["lab"]   # no staging copy either
    with pytest.raises(DatasetError, match=re.escape(str(session / "work.csv")) + ": " + message):
        session_table(session)


def test_times_going_back_no_longer_give_a_negative_rate(tmp_path):
    """The exact reproducer: a work.csv written by `effortface work`, then reversed."""
    session = _lab(tmp_path, b"")
    (session / "work.csv").unlink()
    write_work(session)
    lines = (session / "work.csv").read_text().splitlines()
    (session / "work.csv").write_text("\n".join(lines[:1] + lines[:0:-1]) + "\n")
    with pytest.raises(WorkError, match=r"line 3: t_s: expected times increasing .*found 638 after 639"):
        read_work_csv(session / "work.csv")
