"""Files honour the umask: under ``umask 022`` every file a command writes is 0644, every folder 0755.

Each step runs in a child process started by ``sh -c 'umask 022 && exec ...'``: ``effortface demo``
(a capture through a replayed pseudo-terminal, decode, train, evaluate, synthesize), ``effortface
train``, ``synth`` (both formats), ``agreement --plot``, ``recover`` on a session a crash left
incomplete, and key-frames saved through the annotation model. Then every file and folder they wrote
is walked. (Before the fix the atomic writer made session.json, annotations, model files and synth
CSVs 0600, unreadable to colleagues on a shared lab drive.)
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from effortface.samplelab import repo_lab

ROOT = Path(__file__).resolve().parents[1]
UMASK_022 = ["sh", "-c", 'umask 022 && exec "$@"', "umask-022"]
CLIP = ROOT / "tests" / "data" / "motion" / "cmu_13_29_squats_120fps.bvh"

#: copies two sample sessions (files made anew, so under the child's umask), marks one incomplete as
#: a crash leaves it, and key-frames the other through the annotation model (saved at each edit)
SETUP = """
import json, shutil, sys
from pathlib import Path
from effortface.annotate.annotate_session import AnnotateSession
src, out = Path(sys.argv[1]), Path(sys.argv[2])
crashed = shutil.copytree(src, out / "crashed" / src.name, copy_function=shutil.copyfile)
info = json.loads((crashed / "session.json").read_text())
info["complete"] = False
(crashed / "session.json").write_text(json.dumps(info))
(crashed / "heart_rate.csv").write_text((crashed / "heart_rate.csv").read_text()[:2000])
keyed = shutil.copytree(src, out / "keyed" / src.name, copy_function=shutil.copyfile)
model = AnnotateSession(keyed, "R9")
model.set_key(0.4, frame=2)
model.set_key(0.7, frame=9)
"""


def _run(*cmd: object, cwd: Path) -> subprocess.CompletedProcess:
    done = subprocess.run([*UMASK_022, *map(str, cmd)], capture_output=True, text=True, cwd=cwd, timeout=900)
    assert done.returncode == 0, f"{cmd}: {done.stderr}"
    return done


def _effortface(*args: object) -> list[object]:
    return [sys.executable, "-m", "effortface", *args]


def _wrong_modes(folder: Path) -> tuple[int, list[str]]:
    """How many paths were checked, and those that are not 0644 (files) or 0755 (folders)."""
    paths = [p for p in folder.rglob("*") if not p.is_symlink()]
    wrong = [f"{oct(p.stat().st_mode & 0o777)} {p.relative_to(folder)}" for p in paths
             if p.stat().st_mode & 0o777 != (0o755 if p.is_dir() else 0o644)]
    return len(paths), wrong


@pytest.mark.slow
def test_every_file_a_command_writes_under_umask_022_is_0644(tmp_path) -> None:
    lab = repo_lab()
    if lab is None:
        pytest.skip("not a checkout: run from the repository (the test reads sample_sessions/)")
    out = tmp_path / "out"
    out.mkdir()
    strength = next(p for p in sorted(lab.iterdir()) if p.name.endswith("_strength"))
    _run(sys.executable, "-c", SETUP, strength, out, cwd=out)
    _run(*_effortface("recover", next((out / "crashed").iterdir())), cwd=out)
    _run(*_effortface("demo", "--out", out / "demo", "--capture-seconds", "3", "--max-rows", "60"), cwd=out)
    _run(*_effortface("train", lab, "--out", out / "model", "--max-rows", "60", "--grid", "small"), cwd=out)
    _run(*_effortface("synth", out / "model", CLIP, "--out", out / "synth.csv"), cwd=out)
    _run(*_effortface("synth", "default", CLIP, "--format", "livelink", "--out", out / "livelink.csv"), cwd=out)
    _run(*_effortface("agreement", "--ratings", lab / "reliability" / "ratings.csv", "--plot",
                      out / "agreement.png"), cwd=out)
    checked, wrong = _wrong_modes(out)
    names = {p.name for p in out.rglob("*")}
    assert {"session.json", "R9.json", "model.json", "svr.npz", "face.onnx", "synth.csv", "livelink.csv",
            "agreement.png", "evaluation.md", "heart_rate.csv", "decoded_heart_rate.csv"} <= names
    assert list((out / "demo" / "captured").glob("*/serial/*.serlog"))  # the live capture's raw bytes
    print(f"{checked} files and folders written under umask 022")
    assert wrong == []
