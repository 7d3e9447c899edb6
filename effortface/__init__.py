"""effortface: the face of physical effort, from capture to a runtime that animates characters."""

from effortface.core.version import __version__

__all__ = ["__version__"]
