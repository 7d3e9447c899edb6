"""A CSV field over the csv module's limit (131072 characters) is one line naming the file, never a
``_csv.Error`` traceback (issue 37): the heart-rate table importer and the ``--plan`` reader."""

from __future__ import annotations

from pathlib import Path

import pytest

from effortface.capture_tool.importers.table import read_table
from effortface.capture_tool.plan import read_plan
from effortface.core.errors import UserError

BIG = '"' + "x" * 200_000 + '"'


@pytest.mark.parametrize("read, text", [(read_table, f"t_s,hr_bpm\n0,70\n1,{BIG}\n"),
                                        (read_plan, f"label,start_s,end_s\nrun,0,{BIG}\n")])
def test_a_field_over_the_csv_limit_is_one_line(tmp_path: Path, read, text: str) -> None:
    path = tmp_path / "big.csv"
    path.write_text(text)
    with pytest.raises(UserError, match=r"big\.csv: expected CSV fields of at most 131072 characters, found a "
                                        r"longer one") as caught:
        read(path)
    assert "\n" not in str(caught.value)
