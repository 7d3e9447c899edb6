"""A curves CSV (``effortface synth``'s output read back) with a field over the csv module's limit is one
line naming the file and line, never a ``_csv.Error`` traceback (issue 37)."""

from __future__ import annotations

from pathlib import Path

import pytest

from effortface.core.errors import UserError
from effortface.synth.curves_io import read_curves


def test_a_field_over_the_csv_limit_is_one_line(tmp_path: Path) -> None:
    path = tmp_path / "curves.csv"
    path.write_text("t_s,mouth_open\n0,0.1\n0.1,\"" + "x" * 200_000 + "\"\n")
    with pytest.raises(UserError, match=r"curves\.csv: line 3: expected CSV fields of at most 131072 characters"):
        read_curves(path)
