"""effortface: the face of physical effort, from capture to a runtime that animates characters."""

from effortface import _moved
from effortface.core.version import __version__

_moved.install()

__all__ = ["__version__"]
