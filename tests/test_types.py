"""Type checking is part of the test command: mypy over the whole package passes (configured in
pyproject.toml's [tool.mypy]), strictly for the core and for the runtime with every module it imports."""

from __future__ import annotations

import json
import re
import subprocess
import sys

import pytest

from tests.conftest import ROOT

#: Strict-mode flags set globally in [tool.mypy] rather than per module.
GLOBAL_FLAGS = {"warn_redundant_casts", "warn_unused_ignores"}
#: Numeric modules checked strictly but for warn_return_any (numpy types ndarray arithmetic as Any).
NUMERIC_MODULES = {"effortface.synth.energy", "effortface.synth.face", "effortface.synth.physiology",
                   "effortface.synth.segments"}


def test_mypy_passes() -> None:
    """``python -m mypy`` (the package and the settings of pyproject.toml) finds nothing."""
    done = subprocess.run([sys.executable, "-m", "mypy"], cwd=ROOT, capture_output=True, text=True)
    assert done.returncode == 0, done.stdout + done.stderr
    assert done.stdout.startswith("Success: no issues found"), done.stdout


def _strict_flags() -> set[str]:
    """The flags ``--strict`` enables, as mypy itself lists them in ``--help``."""
    text = subprocess.run([sys.executable, "-m", "mypy", "--help"], capture_output=True, text=True,
                          check=True).stdout
    listing = re.search(r"--strict\s+Strict mode; enables the following flags:(.*?)\n  --", text, re.S)
    assert listing, "mypy --help no longer lists the flags of --strict"
    return {f.replace("-", "_") for f in re.findall(r"--([a-z-]+)", re.sub(r"-\n\s*", "-", listing[1]))}


def _runtime_modules() -> set[str]:
    """The effortface modules ``import effortface.runtime`` loads, in a fresh interpreter."""
    code = ("import json, sys, effortface.runtime; "
            "print(json.dumps(sorted(m for m in sys.modules if m.startswith('effortface'))))")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True)
    return set(json.loads(out.stdout))


def test_the_core_and_the_runtime_are_checked_strictly() -> None:
    """Every Qt-free core module and every module the runtime imports has all of --strict's flags
    (a module the runtime starts to import must join the list)."""
    tomllib = pytest.importorskip("tomllib", reason="tomllib is in the standard library from Python 3.11")
    config = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["mypy"]
    core = {f"effortface.core.{p.stem}" for p in (ROOT / "effortface" / "core").glob("*.py")} - {"effortface.core.__init__"}
    wanted = _runtime_modules() | core | {"effortface.core"}
    strict = _strict_flags() - GLOBAL_FLAGS
    assert GLOBAL_FLAGS <= {k for k, v in config.items() if v is True}
    for module in sorted(wanted):
        flags = {k for o in config["overrides"] if module in o["module"] for k, v in o.items() if v is True}
        missing = strict - flags - ({"warn_return_any"} if module in NUMERIC_MODULES else set())
        assert not missing, f"{module}: add it to the strict overrides of [tool.mypy] (missing {sorted(missing)})"
