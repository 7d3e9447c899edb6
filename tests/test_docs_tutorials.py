"""The guide's tutorials run as written, from an empty folder (issue 40).

Each tutorial page (``docs/guide/tutorial-*.md``) is turned into one shell script, made from the page
itself so the page and the test cannot drift: its ```bash blocks as they are, its ```python blocks
as ``python - <<'PY' ... PY``, in the page's order, under ``set -euo pipefail``. The script runs in a
fresh empty folder with a fresh ``HOME`` (no user cache, no user data, no settings), with ``python``
and ``effortface`` on ``PATH`` being this interpreter and this checkout. Then the test checks what
the tutorial says the reader now has. Commands a page shows only inline (``effortface app`` opening
a window) are not run; the tutorials run their headless form, ``--screenshot``.
"""

from __future__ import annotations

import os
import re
import stat
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import ROOT

GUIDE = ROOT / "docs" / "guide"
FENCE = re.compile(r"^```(\w*)\n(.*?)^```", re.M | re.S)
#: what each tutorial leaves in its folder (relative to the folder the page's first command makes)
RESULTS = {
    "tutorial-record.md": ["my-lab/participants.tsv", "decoded.csv", "capture.png"],
    "tutorial-key.md": ["sample_sessions/P02_20260119-121100_cardio/machine/face_landmarker.csv", "agreement.png"],
    "tutorial-train.md": ["models/lopo/MODEL_CARD.md", "models/kfold/MODEL_CARD.md", "models/lopo/face.onnx"],
    "tutorial-character.md": ["squats.csv", "squats_livelink.csv", "my-model/face.onnx"],
}


def tutorials() -> list[str]:
    return sorted(p.name for p in GUIDE.glob("tutorial-*.md"))


def script(page: Path) -> str:
    """The page's commands as one bash script (bash blocks as written, python blocks through ``python -``)."""
    parts = ["set -euo pipefail"]
    for m in FENCE.finditer(page.read_text(encoding="utf-8")):
        lang, body = m.group(1), m.group(2)
        if lang == "bash":
            parts.append(body.rstrip())
        elif lang == "python":
            parts.append(f"python - <<'PY'\n{body.rstrip()}\nPY")
    return "\n".join(parts) + "\n"


def _shims(folder: Path) -> Path:
    """``python`` (this interpreter) and ``effortface`` (this checkout's) in ``folder/bin``."""
    bin_dir = folder / "bin"
    bin_dir.mkdir()
    (bin_dir / "python").symlink_to(sys.executable)
    shim = bin_dir / "effortface"
    shim.write_text(f'#!/bin/sh\nexec "{sys.executable}" -m effortface "$@"\n')
    shim.chmod(shim.stat().st_mode | stat.S_IXUSR)
    return bin_dir


def test_every_tutorial_block_is_run() -> None:
    """A tutorial shows commands only in ```bash or ```python blocks (which the tests run), never in
    an indented or other block that would escape them; every tutorial names what it leaves."""
    assert tutorials() == sorted(RESULTS), tutorials()
    for name in tutorials():
        text = (GUIDE / name).read_text(encoding="utf-8")
        langs = {m.group(1) for m in FENCE.finditer(text)}
        assert langs <= {"bash", "python"}, (name, langs)
        assert not re.search(r"^    effortface ", text, re.M), f"{name}: an indented command the test would not run"
        first = script(GUIDE / name).splitlines()[1]
        assert first.startswith("mkdir ") and "&& cd " in first, f"{name}: expected to start in a new folder, found {first}"


@pytest.mark.slow
@pytest.mark.parametrize("name", tutorials())
def test_the_tutorial_runs_from_an_empty_folder(name: str, tmp_path: Path) -> None:
    work = tmp_path / "work"
    work.mkdir()
    env = {"HOME": str(tmp_path / "home"), "PATH": f"{_shims(tmp_path)}:/usr/bin:/bin",
           "PYTHONPATH": str(ROOT), "QT_QPA_PLATFORM": "offscreen", "LANG": os.environ.get("LANG", "C.UTF-8")}
    done = subprocess.run(["bash", "-c", script(GUIDE / name)], cwd=work, env=env, capture_output=True, text=True,
                          timeout=900)
    assert done.returncode == 0, f"{name}: the tutorial fails:\n{done.stdout[-3000:]}\n{done.stderr[-4000:]}"
    (folder,) = [p for p in work.iterdir() if p.is_dir()]
    for result in RESULTS[name]:
        assert (folder / result).is_file() and (folder / result).stat().st_size > 0, (name, result)
    if name == "tutorial-record.md":
        decoded = (folder / "decoded.csv").read_text().splitlines()
        assert decoded[0].startswith("t_s,hr_bpm") and len(decoded) > 50, decoded[:3]
        assert "P07\tfemale\t27" in (folder / "my-lab" / "participants.tsv").read_text()
    if name == "tutorial-key.md":
        assert "blind round in sample_sessions/reliability" in done.stdout
    if name == "tutorial-train.md":
        assert done.stdout.count("Held-out face score") == 2
    if name == "tutorial-character.md":
        assert re.search(r"serve: [1-9]\d* frames in, [1-9]\d* out", done.stdout + done.stderr), done.stderr[-2000:]
        assert "mouth_stretch" in done.stdout
