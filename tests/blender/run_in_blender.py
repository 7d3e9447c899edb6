"""Run in Blender's own Python (the ``bpy_python`` fixture) by tests/blender/test_blender_addon.py (not collected).

``python run_in_blender.py MODE SPEC.json OUT.json``: installs the add-on zip as a Blender extension
(``bpy.ops.extensions.package_install_files`` into ``BLENDER_USER_RESOURCES``), then

* ``bake``: imports the BVH with Blender's importer, builds the demo face (seven ARKit shape keys),
  bakes, and writes every shape key's value at every frame of the bake (Blender's evaluation);
* ``errors``: the wrong selections, with the error line each gives and what was keyed;
* ``import``: keys curve files with ``effortface.import_curves`` and writes the keyed values.

Nothing here imports effortface before the extension is installed: the add-on's bundled runtime
(``vendor/``) is what the bake uses (OUT.json says which ``effortface`` was loaded).
"""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

import bpy

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "examples"))
import blender_demo_scene as demo  # noqa: E402


def install(zip_path: str) -> dict:
    t0 = time.perf_counter()
    bpy.ops.extensions.package_install_files(filepath=zip_path, repo="user_default", enable_on_install=True)
    return {"install_s": time.perf_counter() - t0, "effortface_file": sys.modules["effortface"].__file__,
            "operators": [hasattr(bpy.ops.effortface, n) for n in ("bake_face", "import_curves")],
            "modules": {m: sys.modules[m].__file__ for m in ("bpy", "numpy")}, "prefix": sys.prefix}


def values(face, first: int, last: int) -> dict[str, list[float]]:
    """Every shape key's value at every frame, as Blender evaluates it."""
    scene = bpy.context.scene
    out: dict[str, list[float]] = {k: [] for k in demo.ARKIT_KEYS}
    for frame in range(first, last + 1):
        scene.frame_set(frame)
        for k in demo.ARKIT_KEYS:
            out[k].append(face.data.shape_keys.key_blocks[k].value)
    return out


def bake(spec: dict) -> dict:
    armature, face = demo.build_scene(Path(spec["bvh"]), spec.get("seconds"))
    scene = bpy.context.scene
    armature.rotation_euler.z = spec.get("turn_rad", 0.0)  # the whole character turned about the vertical
    armature.location.x += spec.get("shift_m", 0.0)
    t0 = time.perf_counter()
    result = bpy.ops.effortface.bake_face()
    bake_s = time.perf_counter() - t0
    fcurves = face.data.shape_keys.animation_data.action.fcurves
    frames = [k.co[0] for k in fcurves.find('key_blocks["jawOpen"].value').keyframe_points]
    first, last = int(frames[0]), int(frames[-1])
    props = {}
    for name in ("effortface_w_per_kg", "effortface_hr_bpm", "effortface_epoc"):
        fc = armature.animation_data.action.fcurves.find(f'["{name}"]')
        props[name] = [fc.evaluate(f) for f in range(first, last + 1)]
    return {"result": sorted(result), "bake_s": bake_s, "first": first, "last": last,
            "scene_range": [scene.frame_start, scene.frame_end],
            "fps": scene.render.fps / scene.render.fps_base, "values": values(face, first, last), "props": props}


def _try_bake() -> str:
    try:
        return str(bpy.ops.effortface.bake_face())
    except RuntimeError as exc:
        return str(exc).strip()


def _keyed(*obs) -> int:
    """F-curves on the objects and their shape keys (what a bake would add)."""
    n = 0
    for ob in obs:
        for idb in (ob, getattr(ob.data, "shape_keys", None)):
            anim = getattr(idb, "animation_data", None) if idb is not None else None
            if anim and anim.action:
                n += sum(1 for fc in anim.action.fcurves if "effortface" in fc.data_path or "key_blocks" in fc.data_path)
    return n


def errors(spec: dict) -> dict:
    armature, face = demo.build_scene(Path(spec["bvh"]), spec.get("seconds"))
    out = {}
    demo.select(face)  # a mesh active, no armature
    out["no_armature"] = [_try_bake(), _keyed(armature, face)]
    plain = bpy.data.objects.new("Plain", bpy.data.meshes.new("Plain"))
    bpy.context.scene.collection.objects.link(plain)
    demo.select(armature, plain)  # a mesh without shape keys
    out["no_shape_keys"] = [_try_bake(), _keyed(armature, face, plain)]
    bpy.context.view_layer.objects.active = None
    out["nothing_active"] = [_try_bake(), _keyed(armature, face)]
    still = bpy.data.objects.new("Still", bpy.data.armatures.new("Still"))
    bpy.context.scene.collection.objects.link(still)
    demo.select(still, face)  # an armature with no action
    out["no_action"] = [_try_bake(), _keyed(still, face)]
    settings = bpy.context.scene.effortface
    settings.model = str(Path(spec["bvh"]).parent / "no_such_bundle")
    demo.select(armature, face)  # a model folder that is not there
    out["missing_model"] = [_try_bake(), _keyed(armature, face)]
    settings.model = "default"
    armature.rotation_euler.x = 1.5708  # the character laid down by its object: world space, so
    out["lying_down"] = [_try_bake(), _keyed(armature, face)]  # no standing height to tell the unit
    armature.rotation_euler.x = 0.0
    for i, bone in enumerate(armature.data.bones):
        bone.name = f"bone{i:03d}"
    demo.select(armature, face)  # a skeleton no convention maps
    out["unmapped_skeleton"] = [_try_bake(), _keyed(armature, face)]
    bpy.context.scene.effortface.mapping_path = str(Path(spec["bvh"]).with_suffix(".missing.json"))
    out["missing_mapping"] = [_try_bake(), _keyed(armature, face)]
    return out


def import_curves(spec: dict) -> dict:
    demo.clear_scene()
    face = demo.make_face()
    demo.select(face)
    bpy.context.scene.render.fps, bpy.context.scene.render.fps_base = spec["fps"], 1.0
    out = {}
    for path in spec["files"]:
        try:
            result = str(bpy.ops.effortface.import_curves(filepath=path))
        except RuntimeError as exc:
            result = str(exc).strip()
        anim = face.data.shape_keys.animation_data
        keyed = {}
        if anim and anim.action:
            for k in demo.ARKIT_KEYS:
                fc = anim.action.fcurves.find(f'key_blocks["{k}"].value')
                if fc is not None:
                    keyed[k] = [list(p.co) for p in fc.keyframe_points]
        out[path] = {"result": result, "keyed": keyed}
        face.data.shape_keys.animation_data_clear()
    return out


def main() -> int:
    mode, spec_path, out_path = sys.argv[1:4]
    spec = json.loads(Path(spec_path).read_text())
    out = install(spec["zip"])
    out.update({"bake": bake, "errors": errors, "import": import_curves}[mode](spec))
    Path(out_path).write_text(json.dumps(out))
    return 0


if __name__ == "__main__":
    code = main()
    sys.stdout.flush()
    os._exit(code)  # the bpy module can hang at interpreter exit
