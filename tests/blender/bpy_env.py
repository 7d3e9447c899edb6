"""A Python interpreter with Blender as a Python module (``bpy``), apart from the project's.

``bpy`` 4.5 LTS asks for ``numpy<2`` (Blender 4.5 ships numpy 1.26): installed beside the project
it would pull the whole environment back to numpy 1.26. So the Blender tests
(tests/blender/conftest.py) and benchmarks/bench_blender.py run Blender in an interpreter of its
own, which is also what a real Blender is:

* ``EFFORTFACE_BPY_PYTHON`` (a path to a Python whose ``bpy`` imports), if set; else
* a virtual environment made once with ``python -m venv`` and ``pip install`` of the requirement in
  pyproject.toml's ``blender`` extra (read here, never copied), under
  ``$EFFORTFACE_TEST_CACHE`` or ``$XDG_CACHE_HOME/effortface-tests`` or ``~/.cache/effortface-tests``,
  in ``bpy-<hash of the requirement>/``, reused while its ``bpy`` imports. pip's output is kept
  beside it in ``bpy-<hash>.log``, with how long the creation took.

Where ``bpy`` has no wheel (it has them for CPython 3.11 on Linux x86-64, macOS and Windows) or the
package index cannot be reached, :class:`NoBlender` says which in one line (the tests skip).
"""

from __future__ import annotations

import hashlib
import os
import platform
import re
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from packaging.requirements import Requirement

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10, for which bpy 4.5 has no wheel anyway
    tomllib = None  # type: ignore[assignment]

ROOT = Path(__file__).resolve().parents[2]
#: a Python with bpy to use instead of the cached virtual environment
PYTHON_VAR = "EFFORTFACE_BPY_PYTHON"
#: the folder of the test caches (default ``$XDG_CACHE_HOME/effortface-tests``)
CACHE_VAR = "EFFORTFACE_TEST_CACHE"
#: making the environment: pip downloads about 373 MB once (its cache serves later creations)
CREATE_TIMEOUT_S = 15 * 60
#: what pip prints when it cannot reach the package index (urllib3 / requests / socket errors)
UNREACHABLE = re.compile(r"NewConnectionError|Failed to establish a new connection|Name or service not known|"
                         r"Temporary failure in name resolution|nodename nor servname|getaddrinfo failed|"
                         r"ConnectTimeoutError|Read timed out|ProxyError|Network is unreachable|"
                         r"Connection refused|Could not fetch URL|SSLError|ConnectionResetError")


class NoBlender(Exception):
    """No interpreter with bpy here, for a reason that is not a fault of the project (one line)."""


@dataclass(frozen=True)
class BpyPython:
    """An interpreter whose ``bpy`` imports.

    Attributes
    ----------
    python : Path
        The interpreter.
    prefix : Path
        Its ``sys.prefix`` (``bpy`` must be loaded from under it).
    bpy_version : str
        ``bpy.app.version_string``.
    numpy_version : str
        Its numpy's version.
    how : str
        One line: where it came from and, if it was made now, how long that took.
    """

    python: Path
    prefix: Path
    bpy_version: str
    numpy_version: str
    how: str


def blender_requirement(pyproject: Path = ROOT / "pyproject.toml") -> str:
    """The one requirement of pyproject.toml's ``blender`` extra.

    Parameters
    ----------
    pyproject : Path
        The project file.

    Returns
    -------
    str
        The requirement string as written there (version range and marker).
    """
    extras = tomllib.loads(pyproject.read_text())["project"]["optional-dependencies"]
    (spec,) = extras["blender"]
    return str(spec)


def cache_root() -> Path:
    """``$EFFORTFACE_TEST_CACHE``, else ``$XDG_CACHE_HOME/effortface-tests``, else ``~/.cache/effortface-tests``."""
    if os.environ.get(CACHE_VAR):
        return Path(os.environ[CACHE_VAR])
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "effortface-tests"


def venv_dir(spec: str) -> Path:
    """The cached environment's folder for requirement ``spec`` (a new one when the range changes)."""
    return cache_root() / f"bpy-{hashlib.sha256(spec.encode()).hexdigest()[:12]}"


def venv_python(folder: Path) -> Path:
    """The interpreter of the virtual environment in ``folder``."""
    return folder / ("Scripts/python.exe" if sys.platform == "win32" else "bin/python")


def clean_env() -> dict[str, str]:
    """This process's environment without what would let the project's packages leak in."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "PYTHONSTARTUP")}
    env["PYTHONNOUSERSITE"] = "1"
    return env


def probe(python: Path) -> BpyPython | None:
    """``python``'s prefix and bpy and numpy versions, or None if it cannot import bpy."""
    code = "import sys, bpy, numpy; print(sys.prefix); print(bpy.app.version_string); print(numpy.__version__)"
    try:
        done = subprocess.run([str(python), "-c", code], capture_output=True, text=True, env=clean_env(),
                              timeout=300)
    except (OSError, subprocess.TimeoutExpired):
        return None
    lines = done.stdout.splitlines()
    if done.returncode != 0 or len(lines) < 3:
        return None
    return BpyPython(python, Path(lines[-3]), lines[-2], lines[-1], "")


def no_wheel_reason(spec: str) -> str | None:
    """Why this interpreter or platform has no bpy wheel for ``spec``, or None."""
    req = Requirement(spec)
    here = f"{platform.python_implementation()} {platform.python_version()} on {sys.platform} {platform.machine()}"
    if platform.python_implementation() != "CPython" or (req.marker is not None and not req.marker.evaluate()):
        return f"no bpy wheel for {here}: {spec!r} is for CPython 3.11 only"
    supported = {("linux", "x86_64"), ("darwin", "arm64"), ("darwin", "x86_64"), ("win32", "AMD64")}
    if (sys.platform, platform.machine()) not in supported:
        return f"no bpy wheel for {here}: bpy has wheels for Linux x86-64, macOS and Windows x86-64 only"
    return None


def create(spec: str, folder: Path, log: Path) -> float:
    """Make the virtual environment of ``spec`` in ``folder``; the seconds it took.

    Built in a temporary folder beside ``folder`` and renamed into place, so that two test runs at
    once never see half an environment (the second keeps the first's). pip's output goes to ``log``.

    Raises
    ------
    NoBlender
        pip found no wheel for this platform, or could not reach the package index.
    RuntimeError
        Any other failure (timeout included), naming the log.
    """
    folder.parent.mkdir(parents=True, exist_ok=True)
    work = folder.with_name(f"{folder.name}.tmp-{os.getpid()}")
    shutil.rmtree(work, ignore_errors=True)
    t0 = time.monotonic()
    with log.open("w") as out:
        out.write(f"$ {sys.executable} -m venv {work}\n$ pip install {spec!r}\n")
        out.flush()
        try:
            steps = ([sys.executable, "-m", "venv", str(work)],
                     [str(venv_python(work)), "-m", "pip", "install", "--disable-pip-version-check", spec])
            for cmd in steps:
                left_s = CREATE_TIMEOUT_S - (time.monotonic() - t0)
                done = subprocess.run(cmd, stdout=out, stderr=subprocess.STDOUT, env=clean_env(), timeout=left_s)
                if done.returncode != 0:
                    break
        except subprocess.TimeoutExpired:
            shutil.rmtree(work, ignore_errors=True)
            raise RuntimeError(f"making the bpy environment took more than {CREATE_TIMEOUT_S} s (see {log})") from None
    took_s = time.monotonic() - t0
    if done.returncode != 0:
        reason = _why_not(work, spec, log, CREATE_TIMEOUT_S - took_s)
        shutil.rmtree(work, ignore_errors=True)
        if reason:
            raise NoBlender(f"{reason}: {spec!r} (see {log})")
        raise RuntimeError(f"pip install {spec!r} failed (exit {done.returncode}, see {log})")
    with log.open("a") as out:
        out.write(f"created in {took_s:.1f} s\n")
    try:
        os.replace(work, folder)
    except OSError:  # another run put its environment there first: use that one
        shutil.rmtree(work, ignore_errors=True)
    return took_s


def _why_not(work: Path, spec: str, log: Path, left_s: float) -> str | None:
    """After a failed install: the package index unreachable, no bpy wheel for this platform, or None
    (another failure). pip says "No matching distribution" for both; its debug output (``-vv``, a dry
    run appended to ``log``) tells a connection error from links skipped for their platform tags."""
    if "No matching distribution found" not in log.read_text(errors="replace"):
        return None
    with log.open("a") as out:
        out.write(f"$ pip install --dry-run --no-deps --ignore-installed -vv {spec!r}  (why not)\n")
        out.flush()
        try:
            subprocess.run([str(venv_python(work)), "-m", "pip", "install", "--dry-run", "--no-deps",
                            "--ignore-installed", "--disable-pip-version-check", "-vv", spec],
                           stdout=out, stderr=subprocess.STDOUT, env=clean_env(), timeout=max(left_s, 60))
        except (OSError, subprocess.TimeoutExpired):
            pass
    text = log.read_text(errors="replace")
    if "none of the wheel's tags" not in text and UNREACHABLE.search(text):
        return "the package index could not be reached to install bpy"
    return "the package index has no bpy wheel for this platform"


def bpy_python() -> BpyPython:
    """The interpreter with bpy the Blender tests and benchmark use (see the module's docstring).

    Returns
    -------
    BpyPython
        The interpreter, checked to import bpy.

    Raises
    ------
    NoBlender
        No bpy wheel for this platform, or the package index unreachable (one line saying which).
    RuntimeError
        ``EFFORTFACE_BPY_PYTHON`` cannot import bpy, or making the environment failed otherwise.
    """
    given = os.environ.get(PYTHON_VAR)
    if given:
        found = probe(Path(given))
        if found is None:
            raise RuntimeError(f"{PYTHON_VAR}={given}: expected a Python that imports bpy, found none")
        return BpyPython(**{**found.__dict__, "how": f"bpy {found.bpy_version} from {PYTHON_VAR}={given}"})
    if tomllib is None:
        raise NoBlender(f"no bpy wheel for Python {platform.python_version()}: bpy 4.5 is for CPython 3.11 only")
    spec = blender_requirement()
    reason = no_wheel_reason(spec)
    if reason:
        raise NoBlender(reason)
    folder = venv_dir(spec)
    log = folder.with_name(folder.name + ".log")
    found = probe(venv_python(folder)) if folder.is_dir() else None
    if found is not None:
        how = f"bpy {found.bpy_version} (numpy {found.numpy_version}) from the cached environment {folder}"
        return BpyPython(**{**found.__dict__, "how": how})
    shutil.rmtree(folder, ignore_errors=True)  # absent, or there but broken: made again
    took_s = create(spec, folder, log)
    found = probe(venv_python(folder))
    if found is None:
        raise RuntimeError(f"{folder}: made, but its bpy does not import (see {log})")
    how = (f"bpy {found.bpy_version} (numpy {found.numpy_version}): made the environment {folder} "
           f"in {took_s:.0f} s (pip's output: {log})")
    return BpyPython(**{**found.__dict__, "how": how})


if __name__ == "__main__":  # the interpreter's path on stdout (made first if need be), how on stderr
    found = bpy_python()
    print(found.how, file=sys.stderr)
    print(found.python)
