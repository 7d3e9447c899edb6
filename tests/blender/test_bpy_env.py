"""How the Blender tests get their interpreter (tests/blender/bpy_env.py): bpy's requirement read from
pyproject.toml, kept out of the project's environment, and a skip that says which reason."""

from __future__ import annotations

import sys
import venv
from pathlib import Path

import pytest

tomllib = pytest.importorskip("tomllib", reason="tomllib is Python 3.11+ (bpy 4.5 is for CPython 3.11 only)")

from tests.blender import bpy_env
from tests.conftest import ROOT


def test_bpy_is_in_the_blender_extra_only() -> None:
    extras = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]
    assert bpy_env.blender_requirement() == "bpy>=4.5,<4.6; python_version == '3.11'"
    others = [req for name, reqs in extras.items() if name != "blender" for req in reqs]
    assert not any(req.replace(" ", "").startswith("bpy") for req in others), others


def test_the_cached_environment_is_named_after_the_requirement(monkeypatch: pytest.MonkeyPatch,
                                                                tmp_path: Path) -> None:
    monkeypatch.setenv(bpy_env.CACHE_VAR, str(tmp_path))
    a, b = bpy_env.venv_dir("bpy>=4.5,<4.6"), bpy_env.venv_dir("bpy>=5.0,<5.1")
    assert a.parent == b.parent == tmp_path and a != b and a.name.startswith("bpy-")
    monkeypatch.delenv(bpy_env.CACHE_VAR)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert bpy_env.cache_root() == tmp_path / "xdg" / "effortface-tests"


def test_no_wheel_for_another_python_or_machine_says_which(monkeypatch: pytest.MonkeyPatch) -> None:
    reason = bpy_env.no_wheel_reason("bpy>=4.5,<4.6; python_version == '3.99'")
    assert reason is not None and reason.startswith("no bpy wheel for ") and "CPython 3.11 only" in reason
    monkeypatch.setattr(bpy_env.platform, "machine", lambda: "riscv64")
    reason = bpy_env.no_wheel_reason("bpy>=4.5,<4.6")
    assert reason is not None and "riscv64" in reason and "Linux x86-64, macOS and Windows" in reason


def _pip_without_config(monkeypatch: pytest.MonkeyPatch) -> None:
    """pip reads no configuration file (this machine's extra indexes and wheel folder), one try, short timeout."""
    monkeypatch.setenv("PIP_CONFIG_FILE", "/dev/null" if sys.platform != "win32" else "nul")
    monkeypatch.setenv("PIP_RETRIES", "0")
    monkeypatch.setenv("PIP_TIMEOUT", "5")
    monkeypatch.delenv("PIP_FIND_LINKS", raising=False)
    monkeypatch.delenv("PIP_EXTRA_INDEX_URL", raising=False)


def test_an_unreachable_index_is_a_skip_reason_naming_it(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    _pip_without_config(monkeypatch)
    monkeypatch.setenv("PIP_INDEX_URL", "http://127.0.0.1:9/simple")  # the discard port: refused
    folder, log = tmp_path / "bpy-x", tmp_path / "bpy-x.log"
    with pytest.raises(bpy_env.NoBlender, match="the package index could not be reached") as exc:
        bpy_env.create("bpy>=4.5,<4.6", folder, log)
    assert "\n" not in str(exc.value) and str(log) in str(exc.value)
    assert not folder.exists() and not list(tmp_path.glob("bpy-x.tmp-*"))  # no half environment left
    assert "bpy" in log.read_text()


def test_an_index_without_a_bpy_wheel_is_a_skip_reason_naming_it(monkeypatch: pytest.MonkeyPatch,
                                                                  tmp_path: Path) -> None:
    _pip_without_config(monkeypatch)
    monkeypatch.setenv("PIP_NO_INDEX", "1")
    (tmp_path / "wheels").mkdir()
    monkeypatch.setenv("PIP_FIND_LINKS", str(tmp_path / "wheels"))  # an index that has no bpy
    with pytest.raises(bpy_env.NoBlender, match="has no bpy wheel for this platform"):
        bpy_env.create("bpy>=4.5,<4.6", tmp_path / "bpy-x", tmp_path / "bpy-x.log")
    assert not (tmp_path / "bpy-x").exists()


def test_a_given_python_without_bpy_is_refused(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    venv.create(tmp_path / "plain", with_pip=False)  # a Python of its own, without bpy
    for python in (bpy_env.venv_python(tmp_path / "plain"), tmp_path / "no_such_python"):
        monkeypatch.setenv(bpy_env.PYTHON_VAR, str(python))
        with pytest.raises(RuntimeError, match="expected a Python that imports bpy, found none") as exc:
            bpy_env.bpy_python()
        assert str(exc.value).startswith(f"{bpy_env.PYTHON_VAR}={python}:")


def test_blender_runs_apart_from_the_projects_environment(bpy_python: bpy_env.BpyPython) -> None:
    """The interpreter the Blender tests use is not this one, and its numpy is Blender's."""
    assert bpy_python.prefix.resolve() != Path(sys.prefix).resolve()
    assert bpy_python.bpy_version.startswith("4.5") and bpy_python.numpy_version.startswith("1.")
