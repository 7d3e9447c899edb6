"""Build hook: the documents ``--help`` and the Help menu cite ship inside the package.

``docs/*.md`` stay in the repository's ``docs/`` (one copy, no link); a wheel gets them as
``effortface/docs/*.md``, copied into the build folder here. An editable install reads ``docs/``
itself (``effortface.core.docs.DOCS_DIR``). Everything else is in ``pyproject.toml``.
"""

from __future__ import annotations

import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

ROOT = Path(__file__).resolve().parent


class BuildWithDocs(build_py):
    """``build_py`` that also copies ``docs/*.md`` to ``<build>/effortface/docs/``."""

    def run(self) -> None:
        super().run()
        if self.editable_mode:
            return
        target = Path(self.build_lib) / "effortface" / "docs"
        target.mkdir(parents=True, exist_ok=True)
        for doc in sorted((ROOT / "docs").glob("*.md")):
            if not (target / doc.name).exists():
                shutil.copy2(doc, target / doc.name)


setup(cmdclass={"build_py": BuildWithDocs})
