"""A malformed ``mapping`` in a motion/motion.json entry is one line in ``work`` naming the file or the
clip (issue 37: on 72b911b a list gave ``TypeError: expected str, bytes or os.PathLike object, not list``
and ``["a", 5]`` ``TypeError: 'int' object is not subscriptable``)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from effortface.cli import main

ROOT = Path(__file__).resolve().parents[2]
SESSION = ROOT / "sample_sessions" / "P02_20260112-113700_strength"


@pytest.mark.parametrize("mapping, needle", [
    ([1], "motion.json: files[0].mapping: expected a mapping {segment: [proximal, distal]}, found [1]"),
    ("x", "motion.json: files[0].mapping: expected a mapping {segment: [proximal, distal]}, found 'x'"),
    ({"version": 2, "head": ["a", 5]}, "squats_set2.bvh: motion.json mapping: expected [proximal, distal] joint names"),
    ({"pelvis": ["", ""]}, "bad entries: pelvis"),
    ({"version": 1e400}, "motion.json mapping: version: expected 1 or 2, found inf"),
    ({"trunk": ["Hips", "Hips"]}, "trunk 0.00 m: expected 0.3-0.9 m"),
], ids=["list", "string", "int-end", "unknown-segment", "version-inf", "zero-length"])
def test_a_malformed_mapping_entry_is_one_line_in_work(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                       mapping: object, needle: str) -> None:
    session = Path(shutil.copytree(SESSION, tmp_path / SESSION.name, ignore=shutil.ignore_patterns("*.avi", "serial")))
    (session / "work.csv").unlink(missing_ok=True)
    index = session / "motion" / "motion.json"
    doc = json.loads(index.read_text())
    doc["files"][0]["mapping"] = mapping
    index.write_text(json.dumps(doc))
    assert main(["work", str(session)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err and needle in err, err
    assert not (session / "work.csv").exists()
