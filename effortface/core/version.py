"""The one version string of effortface (read by pyproject.toml, session.json and model bundles)."""

__version__ = "0.6.0"
