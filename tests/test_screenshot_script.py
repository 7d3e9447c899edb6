"""docs/screenshots/make_screenshots.py, the one script that retakes the README's screenshots, runs
(two of its groups, into a temporary folder) and leaves the repository's sample lab untouched."""

from __future__ import annotations

import os
import re
import struct
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "docs" / "screenshots" / "make_screenshots.py"
SIZES = ((1280, 800), (1920, 1080))


def _png_size(path: Path) -> tuple[int, int]:
    """(width, height) from a PNG's IHDR chunk."""
    head = path.read_bytes()[:24]
    assert head[:8] == b"\x89PNG\r\n\x1a\n" and head[12:16] == b"IHDR"
    return struct.unpack(">II", head[16:24])


def _lab_state() -> dict[str, int]:
    return {str(p.relative_to(ROOT)): p.stat().st_mtime_ns for p in (ROOT / "sample_sessions").rglob("*")}


def test_the_script_takes_its_screenshots_from_a_copy_of_the_sample_lab(tmp_path: Path) -> None:
    before = _lab_state()
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, (str(ROOT), os.environ.get("PYTHONPATH")))),
           "QT_QPA_PLATFORM": "offscreen"}
    done = subprocess.run([sys.executable, str(SCRIPT), "--only", "app", "annotate", "--out", str(tmp_path)],
                          env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    names = ("app", "annotate_keyframes", "annotate_blind_round", "annotate_reliability")
    expected = {f"{name}_{w}x{h}.png": (w, h) for name in names for w, h in SIZES}
    assert {p.name: _png_size(p) for p in tmp_path.iterdir()} == expected
    assert _lab_state() == before
    assert "docs/screenshots/make_screenshots.py" in _readme_and_guide()


def _readme_and_guide() -> str:
    """The README and the guide's pages (the screenshots moved into the guide with the reference)."""
    pages = [ROOT / "README.md", ROOT / "docs" / "index.md", *sorted((ROOT / "docs" / "guide").glob("*.md"))]
    return "\n".join(p.read_text(encoding="utf-8") for p in pages if p.is_file())


def test_every_screenshot_the_readme_cites_is_there_at_both_sizes() -> None:
    readme = _readme_and_guide()
    cited = set(re.findall(r"screenshots/([a-z_]+)_1280x800\.png", readme))
    assert {"app", "capture_during", "synth_trained", "annotate_keyframes"} <= cited
    for name in cited:
        for w, h in SIZES:
            assert _png_size(ROOT / "docs" / "screenshots" / f"{name}_{w}x{h}.png") == (w, h)
