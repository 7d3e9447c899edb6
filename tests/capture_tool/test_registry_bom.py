"""A ``participants.tsv`` saved by Excel ("CSV UTF-8": a UTF-8 byte-order mark; header cells with trailing
spaces) is read like any other; a UTF-16 one ("Unicode Text") is named by its byte-order mark (issue 37:
refused with an expected and a found that read the same)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from effortface.capture_tool.participants import REGISTRY_TSV, RegistryError, read_registry
from tests.capture_tool.test_participant_truth import LAB_P01, WRONG_P01, _capture, copy_sample_lab

ROOT = Path(__file__).resolve().parents[2]
TSV = (ROOT / "sample_sessions" / REGISTRY_TSV).read_text(encoding="utf-8")


def _spaced(text: str) -> str:
    lines = text.splitlines()
    return "\n".join(["\t".join(c + "  " for c in lines[0].split("\t")), *lines[1:]]) + "\n"


@pytest.mark.parametrize("data", [b"\xef\xbb\xbf" + TSV.encode(), _spaced(TSV).encode(),
                                  b"\xef\xbb\xbf" + _spaced(TSV).replace("\n", "\r\n").encode()],
                         ids=["bom", "trailing-spaces", "bom-spaces-crlf"])
def test_an_excel_saved_registry_reads_as_the_plain_one(tmp_path: Path, data: bytes) -> None:
    path = tmp_path / REGISTRY_TSV
    path.write_bytes(data)
    assert read_registry(path) == read_registry(ROOT / "sample_sessions" / REGISTRY_TSV)
    assert read_registry(path)["P01"] == LAB_P01


def test_a_utf16_registry_names_its_byte_order_mark(tmp_path: Path) -> None:
    path = tmp_path / REGISTRY_TSV
    path.write_bytes(TSV.encode("utf-16"))
    with pytest.raises(RegistryError, match=r"expected UTF-8 text, found UTF-16 \(a byte-order mark FF FE"):
        read_registry(path)


def test_capture_reads_the_labs_record_from_a_registry_with_a_bom(tmp_path: Path) -> None:
    lab = copy_sample_lab(tmp_path / "lab")
    (lab / REGISTRY_TSV).write_bytes(b"\xef\xbb\xbf" + TSV.encode())
    done = _capture(lab, "loop://", "--participant", "P01", *WRONG_P01)
    assert done.returncode == 2, done.stderr
    (line,) = done.stderr.strip().splitlines()
    assert re.search(rf"participant P01: expected the lab's record \(sex female, age 23, training_level 2\.5 in "
                     rf"{re.escape(str(lab / REGISTRY_TSV))}\)", line), line
