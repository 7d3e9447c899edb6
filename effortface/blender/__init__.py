"""The effort face inside Blender: a Blender 4.2+ extension (``blender_manifest.toml`` beside this file).

``effortface blender-addon --out FILE.zip`` builds the installable zip
(:mod:`effortface.blender.package`): this folder's add-on modules at the zip's root, and under
``vendor/`` the numpy runtime they call (``effortface.runtime`` and exactly the modules it imports,
with their data tables). At import, the add-on puts its ``vendor`` folder first on ``sys.path``, so
Blender's own Python (which ships numpy; the runtime needs no scipy) finds that ``effortface``
package. In the repository there is no ``vendor`` folder and the installed package is used.

Only :func:`register` loads ``bpy`` (:mod:`effortface.blender.ui`): importing this package outside
Blender costs nothing.
"""

from __future__ import annotations

import sys
from pathlib import Path

#: the folder of the bundled runtime inside the installed extension
VENDOR = Path(__file__).resolve().parent / "vendor"

if VENDOR.is_dir() and str(VENDOR) not in sys.path:
    sys.path.insert(0, str(VENDOR))


def register() -> None:
    """Blender's entry point: register the operators, the panel and ``Scene.effortface``."""
    from . import ui

    ui.register()


def unregister() -> None:
    """Blender's exit point."""
    from . import ui

    ui.unregister()
