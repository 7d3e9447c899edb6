"""effortface: the face of physical effort, from capture to a runtime that animates characters."""

from pathlib import Path

from effortface.core.version import __version__

#: the simulated lab shipped beside the package (the default of ``effortface app`` and ``demo``)
SAMPLE_LAB = Path(__file__).resolve().parents[1] / "sample_sessions"

__all__ = ["SAMPLE_LAB", "__version__"]
