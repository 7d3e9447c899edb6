"""The sample lab: where ``effortface demo`` and ``effortface app`` find it, wherever effortface is installed.

The lab is not shipped as data (21 MB): its generator is (:mod:`effortface.samplelab.generate`, with
the one real motion clip it needs), and it is deterministic, so every copy is byte-for-byte the
repository's ``sample_sessions/``.

Where the lab is read from (:func:`sample_lab`, used by ``effortface demo``):

- in a checkout (``pip install -e .``), the repository's ``sample_sessions/`` (:func:`repo_lab`);
- otherwise (``pip install .``) a copy built on first use into the user cache,
  ``<cache>/<version>/sample_sessions`` where ``<cache>`` is ``$EFFORTFACE_CACHE_DIR``, else
  ``$XDG_CACHE_HOME/effortface``, else ``~/.cache/effortface`` (:func:`cache_root`). The build takes
  about :data:`BUILD_ESTIMATE_S` seconds and says so on stderr in one line.

Where the app writes (:func:`app_default_dir`, ``effortface app`` with no DIR): a ``sample_sessions``
folder in the current directory if there is one (the user's choice, e.g. the repository's root);
otherwise the user's own copy of the lab in the user data folder, ``<data>/sample_sessions`` where
``<data>`` is ``$EFFORTFACE_DATA_DIR``, else ``$XDG_DATA_HOME/effortface``, else
``~/.local/share/effortface`` (:func:`data_root`). Key-frames and new recordings then go there, never
into a git checkout or site-packages; the window names the folder. An explicit DIR is the user's.
"""

from __future__ import annotations

import os
import secrets
import shutil
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import TextIO

from effortface.core.version import __version__

#: the folder name of the lab, in the repository, the cache and the user data folder
LAB_NAME = "sample_sessions"
#: what a build takes on a 2-core machine, in seconds, for the first-use message (and the guide)
BUILD_ESTIMATE_S = 75  # measured 71 s of CPU with the real faces (issue 23)
CACHE_ENV, DATA_ENV = "EFFORTFACE_CACHE_DIR", "EFFORTFACE_DATA_DIR"
#: the lab's parts a user copy takes (the generator's truth, ``_ground_truth/``, is not a session)
_NOT_COPIED = ("README.md", "generate.py", "_ground_truth", "__pycache__")


def repo_lab() -> Path | None:
    """The repository's ``sample_sessions/`` when effortface runs from a checkout, else None.

    A checkout is recognised by the lab's generator script beside the package
    (``<checkout>/sample_sessions/generate.py``); an installed package has none.
    """
    lab = Path(__file__).resolve().parents[2] / LAB_NAME
    return lab if (lab / "generate.py").is_file() and _has_sessions(lab) else None


def _user_folder(env: str, xdg: str, fallback: tuple[str, ...]) -> Path:
    """``$env``, else ``$xdg/effortface``, else ``~/<fallback>/effortface`` (absolute paths only)."""
    if os.environ.get(env):
        return Path(os.environ[env]).expanduser().resolve()
    base = os.environ.get(xdg, "")
    root = Path(base) if os.path.isabs(base) else Path.home().joinpath(*fallback)
    return root / "effortface"


def cache_root() -> Path:
    """The user cache of effortface: ``$EFFORTFACE_CACHE_DIR``, ``$XDG_CACHE_HOME/effortface`` or ``~/.cache/effortface``."""
    return _user_folder(CACHE_ENV, "XDG_CACHE_HOME", (".cache",))


def data_root() -> Path:
    """The user data folder: ``$EFFORTFACE_DATA_DIR``, ``$XDG_DATA_HOME/effortface`` or ``~/.local/share/effortface``."""
    return _user_folder(DATA_ENV, "XDG_DATA_HOME", (".local", "share"))


def cached_lab_path() -> Path:
    """Where this version's lab is (or will be) built in the cache: ``<cache>/<version>/sample_sessions``."""
    return cache_root() / __version__ / LAB_NAME


def _has_sessions(folder: Path) -> bool:
    return any(folder.glob("*/session.json"))


def sample_lab(stderr: TextIO | None = None) -> Path:
    """The sample lab to read: the checkout's, else the cached copy (built now if missing).

    Parameters
    ----------
    stderr : text stream, optional
        Where the one-line first-use message goes (default ``sys.stderr``).

    Returns
    -------
    Path
    """
    return repo_lab() or ensure_cached_lab(stderr=stderr)


def ensure_cached_lab(stderr: TextIO | None = None) -> Path:
    """The cached lab of this version, built first if it is not there (about BUILD_ESTIMATE_S, said on stderr)."""
    target = cached_lab_path()
    if _has_sessions(target):
        return target
    from effortface.samplelab.generate import build_lab

    return _make_once(target, "building the sample lab", f"about {BUILD_ESTIMATE_S} s, once",
                      lambda tmp: build_lab(tmp, say=_quiet), stderr)


def app_default_dir(cwd: Path | None = None, stderr: TextIO | None = None) -> Path:
    """The sessions folder of ``effortface app`` with no DIR (see the module's docstring for the rule).

    Parameters
    ----------
    cwd : Path, optional
        The current directory (default: ``Path.cwd()``).
    stderr : text stream, optional
        Where the one-line first-use message goes when the user copy is made.

    Returns
    -------
    Path
        ``cwd/sample_sessions`` if it is a folder, else the user copy (made now if missing).
    """
    local = (cwd if cwd is not None else Path.cwd()) / LAB_NAME
    return local if local.is_dir() else user_lab(stderr=stderr)


def user_lab(stderr: TextIO | None = None) -> Path:
    """The user's own, writable copy of the lab, ``<data>/sample_sessions`` (copied now if missing).

    Once made it is the user's: never replaced, whatever it holds.
    """
    target = data_root() / LAB_NAME
    if target.exists():
        return target
    source = sample_lab(stderr=stderr)
    return _make_once(target, f"copying the sample lab from {source}", "yours to edit",
                      lambda tmp: _copy_lab(source, tmp), stderr)


def _copy_lab(source: Path, out: Path) -> None:
    """Copy the sessions and the reliability round of ``source`` into the existing folder ``out``."""
    for item in sorted(source.iterdir()):
        if item.is_dir() and item.name not in _NOT_COPIED:
            shutil.copytree(item, out / item.name)


def _make_once(target: Path, what: str, note: str, make: Callable[[Path], object],
               stderr: TextIO | None) -> Path:
    """Make ``target`` by ``make(tmp)`` in a fresh folder beside it, then rename: never half a lab.

    Two processes racing both build; the first rename wins and the other's copy is discarded.
    One line on ``stderr`` says what, where and how long.
    """
    err = stderr if stderr is not None else sys.stderr
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = target.with_name(f".{target.name}.{os.getpid()}-{secrets.token_hex(4)}.tmp")
    tmp.mkdir()  # not tempfile.mkdtemp: its 0700 would ignore the umask
    print(f"effortface: first use: {what} into {target} ({note})...", end="", file=err, flush=True)
    t0 = time.monotonic()
    outcome = "failed"
    try:
        make(tmp)
        _rename_unless_made(tmp, target)
        outcome = f"done in {time.monotonic() - t0:.0f} s"
    finally:
        print(f" {outcome}", file=err, flush=True)
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    return target


def _rename_unless_made(tmp: Path, target: Path) -> None:
    """Rename ``tmp`` to ``target``, unless another process made ``target`` meanwhile (then keep theirs)."""
    try:
        os.rename(tmp, target)
    except OSError:
        if not target.is_dir():
            raise


def _quiet(_line: str) -> None:
    """Drop the generator's per-session progress lines (the first-use message says enough)."""
