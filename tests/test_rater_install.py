"""The machine rater installs with the default install and leaves OpenCV and Qt as they were (issue 23).

``mediapipe`` would pull ``opencv-contrib-python`` (the GUI build: a second ``cv2`` over the headless
one, with its own Qt plugins); the rater runs on ``ai-edge-litert`` instead. Checked on the installed
distributions (importlib.metadata) and by starting the application's modules beside the rater.
"""

from __future__ import annotations

import importlib.metadata
import os
import subprocess
import sys
from pathlib import Path

from packaging.markers import default_environment
from packaging.requirements import Requirement

ROOT = Path(__file__).resolve().parents[1]
GUI_OPENCV = ("opencv-python", "opencv-contrib-python")


def _requirements() -> list[Requirement]:
    return [Requirement(r) for r in importlib.metadata.requires("effortface") or []]


def test_the_default_install_has_no_gui_build_of_opencv() -> None:
    installed = {(d.metadata["Name"] or "").lower() for d in importlib.metadata.distributions()}
    assert not installed & set(GUI_OPENCV), sorted(installed & set(GUI_OPENCV))
    assert "opencv-contrib-python-headless" in installed


def test_effortface_requires_litert_where_it_has_wheels_and_never_mediapipe_or_gui_opencv() -> None:
    requirements = {r.name: r for r in _requirements() if r.marker is None or "extra" not in str(r.marker)}
    assert "mediapipe" not in requirements and not set(GUI_OPENCV) & set(requirements)
    litert = requirements["ai-edge-litert"]
    assert str(litert.specifier) in (">=2.3,<3", "<3,>=2.3")
    environments = {  # (sys_platform, platform_machine) -> wheels exist
        ("linux", "x86_64"): True, ("linux", "aarch64"): True, ("darwin", "arm64"): True,
        ("win32", "AMD64"): True, ("darwin", "x86_64"): False, ("linux", "armv7l"): False,
    }
    for (platform, machine), wanted in environments.items():
        env = {**default_environment(), "sys_platform": platform, "platform_machine": machine}
        assert litert.marker is not None and litert.marker.evaluate(env) is wanted, (platform, machine)


def test_the_app_starts_beside_the_rater() -> None:
    """PySide6's application, OpenCV and the TFLite interpreter in one process, the rater run once."""
    code = (
        "import numpy as np\n"
        "from PySide6.QtWidgets import QApplication\n"
        "import effortface.app, effortface.cli, effortface.annotate.gui.annotate_stage\n"
        "from effortface.annotate.machine.landmarker import FaceLandmarker\n"
        "app = QApplication([])\n"
        "result = FaceLandmarker().process(np.zeros((480, 640, 3), np.uint8))\n"
        "import cv2, sys\n"
        "print(result.face, cv2.__file__, 'cv2.qt' in sys.modules)\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, cwd=ROOT,
                          env={**os.environ, "QT_QPA_PLATFORM": "offscreen"})
    assert done.returncode == 0, done.stderr[-3000:]
    face, cv2_file, cv2_qt = done.stdout.split()
    assert face == "False" and cv2_qt == "False"
    dist = importlib.metadata.distribution("opencv-contrib-python-headless")
    assert Path(cv2_file).resolve().is_relative_to(Path(str(dist.locate_file(""))).resolve())
