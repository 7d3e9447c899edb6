"""effortface: the face of physical effort, from capture to a runtime that animates characters."""

__version__ = "0.1.0"
