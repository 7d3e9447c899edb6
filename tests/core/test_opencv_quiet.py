"""OpenCV is imported in one place, with its own log silenced (issue 16, 14: OpenCV's warnings came
before our one-line errors)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _package_sources() -> list[Path]:
    out = [p for folder in ("capture_tool", "annotate", "train") for p in (ROOT / folder).rglob("*.py")]
    out += [p for p in (ROOT / "effortface").rglob("*.py")
            if p.relative_to(ROOT / "effortface").parts[0] not in ("capture_tool", "annotate", "train")]
    return out


def test_only_core_opencv_imports_cv2() -> None:
    importing = [p.relative_to(ROOT).as_posix() for p in _package_sources()
                 if re.search(r"^\s*(import cv2|from cv2 import)", p.read_text(encoding="utf-8"), re.M)]
    assert importing == ["effortface/core/opencv.py"]


def _log_level(env_extra: dict[str, str]) -> int:
    code = ("import cv2; from effortface.core.opencv import import_cv2; import_cv2(); "
            "print(cv2.utils.logging.getLogLevel())")
    env = {k: v for k, v in os.environ.items() if k != "OPENCV_LOG_LEVEL"}
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                          env={**env, **env_extra}, cwd=ROOT)
    return int(done.stdout)


def test_import_cv2_silences_opencv_unless_the_user_asks() -> None:
    import cv2

    assert _log_level({}) == cv2.utils.logging.LOG_LEVEL_SILENT
    assert _log_level({"OPENCV_LOG_LEVEL": "DEBUG"}) == cv2.utils.logging.LOG_LEVEL_DEBUG
