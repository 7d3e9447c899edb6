"""Installs that work anywhere (issue 13, Must show): a non-editable ``pip install .`` in a fresh venv,
and the runtime alone (``runtime-dist/``, the ``effortface-runtime`` distribution) in a plain venv.

Both build from a copy of the repository's sources (a build writes ``*.egg-info`` and ``build/`` beside
them), with pip as users run it: the build back-end comes from the package registry (pip's cache
after the first run). The full install uses a venv with ``--system-site-packages`` for the heavy
dependencies and ``--no-deps``; the runtime's venv is plain and pip installs numpy and scipy itself.
Every child runs without PYTHONPATH, from an empty folder holding a user's own ``train.py``.
"""

from __future__ import annotations

import json
import os
import shutil
import site
import subprocess
import sys
import time
import venv
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
#: what a distribution is built from (the stage folders are reached through effortface/'s links)
SOURCES = ("pyproject.toml", "setup.py", "README.md", "effortface", "capture_tool", "annotate", "train", "docs",
           "runtime-dist")
HEAVY = ("PySide6", "cv2", "pandas", "sklearn", "onnxruntime", "matplotlib")
CLIP = ROOT / "tests" / "data" / "motion" / "cmu_13_29_squats_120fps.bvh"
#: a game's own train.py: it must not hide the runtime (the old top-level ``train.runtime`` it did)
USER_TRAIN_PY = "raise SystemExit(\"the user's train.py was imported instead of effortface's code\")\n"
#: imports the runtime, loads the built-in model, animates a clip; prints the heavy modules loaded
RUNTIME_CHECK = f"""
import json, sys
from effortface.runtime import Character, load_model
curves = load_model("default").synthesize({str(CLIP)!r}, Character(age=30, sex="male", height_m=1.78,
                                          mass_kg=75, training_level=5))
print(json.dumps({{"heavy": sorted(m for m in {HEAVY!r} if m in sys.modules),
                  "file": sys.modules["effortface"].__file__, "frames": len(curves["t_s"])}}))
"""


def _clean_env(**extra: str) -> dict[str, str]:
    """The environment without PYTHONPATH (which would put the checkout before the install)."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    return {**env, "PYTHONNOUSERSITE": "1", **extra}


def _run(cmd: list, cwd: Path, timeout: float = 600, **env: str) -> subprocess.CompletedProcess:
    done = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, cwd=cwd,
                          env=_clean_env(**env), timeout=timeout)
    assert done.returncode == 0, f"{cmd}: exit {done.returncode}\n{done.stdout[-2000:]}\n{done.stderr[-4000:]}"
    return done


@pytest.fixture(scope="module")
def sources(tmp_path_factory) -> Path:
    """A copy of the files a distribution is built from (links kept, no caches)."""
    out = tmp_path_factory.mktemp("src")
    ignore = shutil.ignore_patterns("__pycache__", "*.egg-info", "build", "dist")
    for name in SOURCES:
        src = ROOT / name
        if not src.exists():
            continue
        if src.is_dir():
            shutil.copytree(src, out / name, symlinks=True, ignore=ignore)
        else:
            shutil.copy2(src, out / name)
    return out


def _venv(folder: Path, system_site_packages: bool) -> Path:
    """A fresh venv with pip; returns its ``bin`` folder."""
    venv.EnvBuilder(with_pip=True, system_site_packages=system_site_packages, clear=True).create(folder)
    bin_ = folder / ("Scripts" if sys.platform == "win32" else "bin")
    if system_site_packages and sys.prefix != sys.base_prefix:
        # the tests run in a venv (as a newcomer runs them): the inner venv sees the base interpreter's
        # packages, not this venv's, so a .pth file adds this venv's site-packages (pandas & co)
        inner = _run([bin_ / "python", "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                     folder).stdout.strip()
        outer = [p for p in site.getsitepackages() if Path(p).is_dir()]
        (Path(inner) / "_outer_venv.pth").write_text("\n".join(outer) + "\n")
    return bin_


def _user_folder(tmp_path: Path) -> Path:
    """An empty folder but for a user's own ``train.py``."""
    work = tmp_path / "game"
    work.mkdir()
    (work / "train.py").write_text(USER_TRAIN_PY)
    return work


def _runtime_check(python: Path, work: Path) -> dict:
    return json.loads(_run([python, "-c", RUNTIME_CHECK], work).stdout)


@pytest.mark.slow
def test_the_runtime_alone_installs_into_a_plain_venv(sources, tmp_path) -> None:
    """``pip install ./runtime-dist``: numpy and scipy come with it, nothing else; the runtime works."""
    bin_ = _venv(tmp_path / "venv", system_site_packages=False)
    _run([bin_ / "python", "-m", "pip", "install", "-q", sources / "runtime-dist"], tmp_path)
    listed = json.loads(_run([bin_ / "python", "-m", "pip", "list", "--format", "json"], tmp_path).stdout)
    assert {p["name"].lower() for p in listed} - {"pip", "setuptools", "wheel"} == {
        "effortface-runtime", "numpy", "scipy"}
    work = _user_folder(tmp_path)
    got = _runtime_check(bin_ / "python", work)
    assert got["heavy"] == [] and got["frames"] > 100
    assert Path(got["file"]).is_relative_to(tmp_path / "venv")
    for name in HEAVY[:4]:  # not merely unloaded: absent
        assert subprocess.run([bin_ / "python", "-c", f"import {name}"], cwd=work, env=_clean_env(),
                              capture_output=True).returncode == 1
    files = _run([bin_ / "python", "-c", "import effortface, pathlib; p = pathlib.Path(effortface.__file__).parent; "
                  "print(sorted(str(f.relative_to(p)) for f in p.rglob('*.py')))"], work).stdout
    assert "cli.py" not in files and "capture_tool" not in files and "runtime.py" in files


def _local_annotate_and_train(folder: Path) -> list[Path]:
    """Local distributions named ``annotate`` and ``train`` that install top-level ``annotate`` and
    ``train`` packages, as the package index's projects of those names do (a test installs no code of
    unknown provenance: these stand-ins are written here)."""
    dists = []
    for name in ("annotate", "train"):
        project = folder / "local" / name
        (project / name).mkdir(parents=True)
        (project / name / "__init__.py").write_text(f'"""A stand-in for the PyPI package {name}."""\nruntime = None\n')
        (project / "pyproject.toml").write_text(
            f'[build-system]\nrequires = ["setuptools>=68"]\nbuild-backend = "setuptools.build_meta"\n'
            f'[project]\nname = "{name}"\nversion = "9.9"\n[tool.setuptools]\npackages = ["{name}"]\n')
        dists.append(project)
    return dists


@pytest.mark.slow
def test_pip_install_dot_in_a_fresh_venv_works_from_any_folder(sources, tmp_path) -> None:
    """The issue's Must show: ``pip install .``; then, from an empty folder holding a ``train.py``, the
    runtime loads no Qt, OpenCV, pandas or scikit-learn; distributions named ``annotate`` and
    ``train`` (as on the package index) install alongside and break nothing; ``effortface demo`` works, building the sample lab into the
    user cache on first use."""
    bin_ = _venv(tmp_path / "venv", system_site_packages=True)
    _run([bin_ / "python", "-m", "pip", "install", "-q", "--no-deps", sources], tmp_path)
    files = _run([bin_ / "python", "-c", "import importlib.metadata as m; "
                  "print('\\n'.join(str(f) for f in m.files('effortface')))"], tmp_path).stdout.split()
    from effortface import __version__

    # one installed namespace: nothing at top level but effortface (and the `effortface` script)
    assert {f.split("/")[0] for f in files if not f.startswith("..")} == {"effortface",
                                                                          f"effortface-{__version__}.dist-info"}
    assert "effortface/samplelab/data/cmu_13_29_squats_120fps.bvh" in files  # the lab builds anywhere
    assert {"effortface/samplelab/data/faces/astronaut.jpg", "effortface/samplelab/data/faces/astronaut_landmarks.npy",
            "effortface/samplelab/data/faces/PROVENANCE.md"} <= set(files)  # its real faces too
    assert {"effortface/docs/DESIGN.md", "effortface/docs/SCIENCE.md"} <= set(files)  # what --help cites
    work = _user_folder(tmp_path)
    got = _runtime_check(bin_ / "python", work)
    assert got["heavy"] == [] and Path(got["file"]).is_relative_to(tmp_path / "venv")

    others = _local_annotate_and_train(tmp_path)
    _run([bin_ / "python", "-m", "pip", "install", "-q", "--no-deps", *others], tmp_path)
    # theirs are installed at top level (found, not run: the PyPI ones need their own dependencies)
    tops = _run([bin_ / "python", "-c", "import importlib.util as u, effortface.annotate.agreement, "
                 "effortface.synth.runtime; print(u.find_spec('annotate').origin, u.find_spec('train').origin)"],
                tmp_path).stdout.split()
    assert [Path(t).relative_to(tmp_path / "venv").parts[-2:] for t in tops] == [
        ("annotate", "__init__.py"), ("train", "__init__.py")]
    assert _runtime_check(bin_ / "python", work)["heavy"] == []

    cache = tmp_path / "cache"
    t0 = time.monotonic()
    demo = _run([bin_ / "effortface", "demo", "--out", work / "demo", "--capture-seconds", "4", "--max-rows", "60"],
                work, timeout=900,
                EFFORTFACE_CACHE_DIR=str(cache), QT_QPA_PLATFORM="offscreen")
    print(f"effortface demo from an installed package, lab built first: {time.monotonic() - t0:.0f} s")
    from effortface import __version__

    lab = cache / __version__ / "sample_sessions"
    assert f"effortface: first use: building the sample lab into {lab}" in demo.stderr
    assert demo.stdout.strip().splitlines()[-1] == f"report: {work / 'demo' / 'model' / 'report' / 'report.md'}"
    agreement = _run([bin_ / "effortface", "agreement", "--ratings", lab / "reliability" / "ratings.csv"], work)
    assert "R1" in agreement.stdout
    assert sorted(p.name for p in work.iterdir()) == ["demo", "train.py"]  # nothing else written here
