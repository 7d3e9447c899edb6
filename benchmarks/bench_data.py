"""Where the benchmarks find the real clips: ``../shared/data`` beside the repository (the lab's
copy) if it is there, else the repository's own ``tests/data`` (the same layout), so that the
benchmarks also run on a fresh clone."""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def data_dir() -> Path:
    """The first of ``../shared/data`` and ``tests/data`` that holds a ``motion`` folder."""
    for candidate in (ROOT.parent / "shared" / "data", ROOT / "tests" / "data"):
        if (candidate / "motion").is_dir():
            return candidate
    raise SystemExit(f"benchmark data: expected {ROOT.parent / 'shared' / 'data'} or "
                     f"{ROOT / 'tests' / 'data'} with a motion folder, found neither")


DATA = data_dir()
