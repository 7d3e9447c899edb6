"""The real data the tests read is in the repository (tests/data), whole and with its licences."""

from __future__ import annotations

import hashlib
from pathlib import Path

from tests.conftest import SHARED_DATA


def test_serial_captures_match_their_sha256sums() -> None:
    sums = (SHARED_DATA / "serial" / "SHA256SUMS").read_text().splitlines()
    assert len(sums) >= 10
    for line in sums:
        digest, name = line.split(maxsplit=1)
        data = (SHARED_DATA / "serial" / name).read_bytes()
        assert hashlib.sha256(data).hexdigest() == digest, name


def test_every_data_folder_keeps_its_licence_or_provenance() -> None:
    for folder in ("serial/zephyr-bt", "serial/njcant", "serial/libant"):
        assert (SHARED_DATA / folder / "LICENSE").is_file(), folder
    assert (SHARED_DATA / "motion_and_physiology_PROVENANCE.md").is_file()
    assert (SHARED_DATA / "PROVENANCE.md").is_file()


def test_data_does_not_come_from_outside_the_repository() -> None:
    root = Path(__file__).resolve().parents[1]
    assert SHARED_DATA.resolve().is_relative_to(root)
