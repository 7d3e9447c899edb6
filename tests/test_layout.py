"""One real package tree, one room per job (docs/guide/layout.md).

restructure: keep old names (the alias test imports old paths on purpose)

Before ``tools/restructure.py`` has run (the stage folders still reached through links), the tests
of the new layout skip, saying so; after it they must pass.
"""

from __future__ import annotations

import importlib
import json
import os
import re
import subprocess
import sys
import venv
from pathlib import Path

import pytest

from effortface import _moved
from tests.conftest import ROOT, product_sources

sys.path.insert(0, str(ROOT / "tools"))
import room_sizes  # noqa: E402

#: the old layout: stage folders reached through links (tools/restructure.py not run yet)
OLD_LAYOUT = (ROOT / "effortface" / "train").is_symlink()
new_layout_only = pytest.mark.skipif(OLD_LAYOUT, reason="the stages are still links: run tools/restructure.py")
SKIP_MARK = "restructure: keep old names"


@new_layout_only
def test_the_repository_holds_no_symbolic_link() -> None:
    listing = subprocess.run(["git", "ls-files", "-s"], cwd=ROOT, capture_output=True, text=True, check=True).stdout
    links = [line.split("\t")[1] for line in listing.splitlines() if line.startswith("120000")]
    assert links == []


@new_layout_only
def test_no_room_holds_more_than_a_third_of_the_code() -> None:
    sizes = room_sizes.room_sizes()
    total = sum(sizes.values())
    too_big = {room: f"{100 * n / total:.1f} %" for room, n in sizes.items() if n > total / 3}
    assert not too_big, too_big


def test_room_sizes_counts_code_not_blanks_or_comments(tmp_path: Path) -> None:
    src = tmp_path / "m.py"
    src.write_text('"""Doc."""\n\n# a comment\nx = 1  # counted\n    \n')
    assert room_sizes.code_lines(src) == 2
    assert room_sizes.room_of(Path("effortface/synth/motion.py")) == "effortface/synth/"
    assert room_sizes.room_of(Path("effortface/cli.py")) == "effortface/*.py (front door)"


@new_layout_only
def test_importing_the_runtime_loads_no_training_module() -> None:
    code = ("import sys, json, effortface.runtime; "
            "print(json.dumps(sorted(m for m in sys.modules if m.startswith('effortface.'))))")
    loaded = json.loads(subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True,
                                       check=True).stdout)
    assert "effortface.runtime" in loaded
    assert [m for m in loaded if m.split(".")[1] in ("train", "interop", "capture_tool", "annotate")] == []


def _old_names_used(text: str) -> list[str]:
    """Old dotted names (keys of effortface._moved.MOVED) that ``text`` uses."""
    return sorted({m.group(0) for m in re.finditer(r"\beffortface(?:\.\w+)+", text) if _moved.new_name(m.group(0))})


def test_our_code_never_uses_an_old_import_path() -> None:
    """pyproject's filterwarnings make DeprecationWarnings errors only where they are attributed to
    effortface; the alias finder warns from the import system, so the sources are checked here."""
    files = [*product_sources(), *sorted((ROOT / "tests").rglob("*.py")), *sorted((ROOT / "benchmarks").glob("*.py")),
             ROOT / "pyproject.toml", ROOT / "runtime-dist" / "setup.py"]
    used = {}
    for path in files:
        text = path.read_text(encoding="utf-8")
        if SKIP_MARK not in text and (found := _old_names_used(text)):
            used[path.relative_to(ROOT).as_posix()] = found
    assert not used, used


@pytest.mark.skipif(not _moved.MOVED, reason="nothing moved yet: run tools/restructure.py")
def test_an_old_import_path_gives_the_same_module_with_a_warning() -> None:
    old, new = sorted(_moved.MOVED.items())[0]
    for name in [n for n in sys.modules if n == old or n.startswith(old + ".")]:
        del sys.modules[name]
    with pytest.warns(DeprecationWarning, match=f"{re.escape(old)} moved to {re.escape(new)}"):
        aliased = importlib.import_module(old)
    assert aliased is importlib.import_module(new)
    assert aliased.__spec__.name == new  # the shared module keeps its own spec


def test_the_restructure_script_has_nothing_left_to_do_or_a_plan() -> None:
    """A dry run lists the moves before the restructure and none after it (the script is idempotent)."""
    done = subprocess.run([sys.executable, str(ROOT / "tools" / "restructure.py"), "--dry-run"], cwd=ROOT,
                          capture_output=True, text=True, check=True).stdout
    moves = [line for line in done.splitlines() if line.startswith(("git mv", "remove link"))]
    if OLD_LAYOUT:
        assert "remove link effortface/train" in moves and "git mv train effortface/train" in moves
    else:
        assert moves == []


@pytest.mark.slow
@new_layout_only
def test_a_clone_without_symlinks_installs_and_imports_every_stage_from_its_own_files(tmp_path: Path) -> None:
    """What Git on Windows does by default (``core.symlinks=false``): the clone installs editable and
    every stage imports from the clone's own files."""
    clone = tmp_path / "clone"
    subprocess.run(["git", "-c", "core.symlinks=false", "clone", "-q", str(ROOT), str(clone)], check=True)
    venv.EnvBuilder(system_site_packages=True, with_pip=True, clear=True).create(tmp_path / "venv")
    python = tmp_path / "venv" / ("Scripts/python.exe" if sys.platform == "win32" else "bin/python")
    inner = subprocess.run([python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                           capture_output=True, text=True, check=True).stdout.strip()
    import site

    # this venv's packages (numpy, setuptools...) for the inner venv, not the base interpreter's only
    (Path(inner) / "_outer_venv.pth").write_text("\n".join(site.getsitepackages()) + "\n")
    env = {**{k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")},
           "PATH": str(python.parent) + os.pathsep + os.environ.get("PATH", ""), "PYTHONNOUSERSITE": "1"}
    # the build back-end from the package registry, as tests/test_install.py (pip's cache after the first run)
    install = subprocess.run([python, "-m", "pip", "install", "-q", "--no-deps", "-e", str(clone)], cwd=tmp_path,
                             capture_output=True, text=True, env=env, timeout=600)
    assert install.returncode == 0, install.stderr[-3000:]
    code = ("import json, effortface.capture_tool, effortface.annotate, effortface.train, effortface.runtime as r; "
            "import effortface.capture_tool as c, effortface.annotate as a, effortface.train as t; "
            "print(json.dumps([m.__file__ for m in (c, a, t, r)]))")
    done = subprocess.run([python, "-c", code], cwd=tmp_path, capture_output=True, text=True, env=env)
    assert done.returncode == 0, done.stderr[-3000:]
    for file in json.loads(done.stdout):
        assert Path(file).resolve().is_relative_to(clone.resolve()), file


def test_the_tests_mirror_the_package_rooms() -> None:
    """One test folder per room of effortface/ (the front door's commands in tests/commands/), and no
    other folder of tests but data/: a test of effortface/synth/ is found in tests/synth/."""
    rooms = {p.parent.name for p in (ROOT / "effortface").glob("*/__init__.py")}
    folders = {p.parent.name for p in (ROOT / "tests").glob("*/__init__.py")}
    assert folders == rooms
    stray = [p.relative_to(ROOT).as_posix() for p in (ROOT / "tests").glob("*/*/test_*.py")]
    assert stray == []
    named_after_rounds = [p.name for p in (ROOT / "tests").rglob("test_*round*.py")]
    assert named_after_rounds == []
