"""The public runtime: what game code and animation tools import. numpy and scipy only.

::

    from effortface.runtime import load_model, Character, read_motion, motion_from_positions
    model = load_model("default")                   # or a bundle folder written by `effortface train`
    hero = Character(age=30, sex="male", height_m=1.78, mass_kg=75, training_level=5)
    curves = model.synthesize("clip.bvh", hero)
    live = model.stream(hero, skeleton)             # one step per frame

Importing this module loads no Qt, OpenCV, pandas or scikit-learn (checked by
``tests/test_import_rules.py`` in a fresh interpreter). The implementation lives in
:mod:`effortface.synth.runtime` and the modules it imports.
"""

from effortface.synth.motion import Motion, motion_from_positions, read_motion
from effortface.synth.runtime import CURVE_COLUMNS, Character, FaceModel, load_model

__all__ = ["CURVE_COLUMNS", "Character", "FaceModel", "Motion", "load_model", "motion_from_positions",
           "read_motion"]
