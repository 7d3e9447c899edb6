"""Every Python example of the README and the guide runs as it is written (a newcomer copies them).

Each ```python block runs in a fresh interpreter from the repository root (examples may read the
repository's files, e.g. the sample lab's clip); a block that needs another block's names is a bug.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

from tests.conftest import ROOT

FENCE = re.compile(r"^```python\n(.*?)^```", re.M | re.S)


def examples() -> list[tuple[str, str]]:
    """(where, code) of every ```python block in README.md and docs/**/*.md."""
    out = []
    for page in [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]:
        if page.name.startswith("tutorial-"):  # run in order, from an empty folder: tests/test_docs_tutorials.py
            continue
        text = page.read_text(encoding="utf-8")
        for k, m in enumerate(FENCE.finditer(text)):
            line = text[:m.start()].count("\n") + 1
            out.append((f"{page.relative_to(ROOT).as_posix()}:{line}", m.group(1)))
    return out


def test_the_examples_are_found() -> None:
    where = [w for w, _ in examples()]
    assert any(w.startswith("README.md:") for w in where), where
    assert sum(w.startswith("docs/guide/extend-") for w in where) >= 4, where


@pytest.mark.parametrize(("where", "code"), examples(), ids=[w for w, _ in examples()])
def test_the_example_runs(where: str, code: str, tmp_path: Path) -> None:
    done = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=300,
                          env={"PYTHONPATH": "", "HOME": str(tmp_path), "PATH": "/usr/bin:/bin",
                               "QT_QPA_PLATFORM": "offscreen"})
    assert done.returncode == 0, f"{where}: the example fails:\n{done.stderr[-3000:]}"
