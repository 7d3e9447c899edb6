"""The Blender tests' interpreter: a Python with ``bpy`` apart from the project's (tests/blender/bpy_env.py).

``bpy`` 4.5 asks for numpy<2, so it is never installed beside the project: the fixture
:func:`bpy_python` gives ``EFFORTFACE_BPY_PYTHON`` or a virtual environment made once under the test
cache with pyproject.toml's ``blender`` extra. Where bpy has no wheel or the package index cannot be
reached, the tests that need it skip, saying which (``pytest -rs``). The end of the run says where the
interpreter came from and how long making it took.
"""

from __future__ import annotations

import pytest

from tests.blender.bpy_env import BpyPython, NoBlender, bpy_python as find_bpy_python

_HOW = pytest.StashKey[str]()


@pytest.fixture(scope="session")
def bpy_python(request: pytest.FixtureRequest) -> BpyPython:
    """The interpreter with bpy (made and cached on first use; skips if bpy cannot be had here)."""
    try:
        found = find_bpy_python()
    except NoBlender as exc:
        request.config.stash[_HOW] = f"no bpy: {exc}"
        pytest.skip(str(exc))
    request.config.stash[_HOW] = found.how
    return found


def pytest_terminal_summary(terminalreporter: pytest.TerminalReporter, config: pytest.Config) -> None:
    """One line: the Blender tests' interpreter, and how long making it took."""
    how = config.stash.get(_HOW, None)
    if how is not None:
        terminalreporter.write_line(f"Blender tests: {how}")
