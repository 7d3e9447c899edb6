"""A demo scene for the effortface Blender add-on, built from nothing (no .blend file).

Run it inside Blender, or with Blender as a Python module in a Python of its own (bpy 4.5 pins
numpy<2, so not beside effortface's environment: ``tests/blender/bpy_env.py`` prints the Blender tests'
interpreter, making it first if need be), this checkout on PYTHONPATH::

    PYTHONPATH=. "$(python tests/blender/bpy_env.py)" examples/blender_demo_scene.py [--bvh CLIP.bvh] \
        [--seconds S] [--render DIR]
    blender --background --python examples/blender_demo_scene.py -- --render DIR

It imports the sample squats clip (``effortface/samplelab/data/cmu_13_29_squats_120fps.bvh``) with
Blender's own BVH importer (the scene takes the file's rate and duration), builds a simple head whose
mesh has the seven ARKit shape keys the add-on keys (``jawOpen``, ``mouthStretchLeft/Right``,
``eyeSquintLeft/Right``, ``browDownLeft/Right``), selects it with the armature active and runs
``bpy.ops.effortface.bake_face()``. With ``--render DIR`` it renders the face at rest and at the bake's
strongest frame (Workbench, small) to ``DIR/blender_face_before.png`` and ``blender_face_after.png``.
The add-on is used as installed (Blender's extensions) or, when it is not, registered from the
``effortface`` package this Python imports.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import bpy
import numpy as np

SAMPLE_BVH = Path(__file__).resolve().parent.parent / "effortface" / "samplelab" / "data" / "cmu_13_29_squats_120fps.bvh"
#: the seven ARKit shape keys of the face, as (name, part, how it moves)
ARKIT_KEYS = ("jawOpen", "mouthStretchLeft", "mouthStretchRight", "eyeSquintLeft", "eyeSquintRight",
              "browDownLeft", "browDownRight")


def _ellipsoid(center: tuple[float, float, float], radii: tuple[float, float, float],
               n_u: int = 24, n_v: int = 12) -> tuple[np.ndarray, list[tuple[int, ...]]]:
    """Vertices and quad/triangle faces of a UV ellipsoid."""
    verts = [(0.0, 0.0, 1.0)]
    for i in range(1, n_v):
        theta = np.pi * i / n_v
        for j in range(n_u):
            phi = 2 * np.pi * j / n_u
            verts.append((np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)))
    verts.append((0.0, 0.0, -1.0))
    faces: list[tuple[int, ...]] = [(0, 1 + (j + 1) % n_u, 1 + j) for j in range(n_u)]
    for i in range(n_v - 2):
        a, b = 1 + i * n_u, 1 + (i + 1) * n_u
        faces += [(a + j, a + (j + 1) % n_u, b + (j + 1) % n_u, b + j) for j in range(n_u)]
    last, base = len(verts) - 1, 1 + (n_v - 2) * n_u
    faces += [(base + j, base + (j + 1) % n_u, last) for j in range(n_u)]
    return np.asarray(verts) * radii + center, faces


#: the head's parts: name -> (center, radii); the face looks along -Y
PARTS = {
    "head": ((0.0, 0.0, 0.0), (1.0, 0.95, 1.2)),
    "eye_L": ((0.38, -0.82, 0.25), (0.2, 0.12, 0.13)),
    "eye_R": ((-0.38, -0.82, 0.25), (0.2, 0.12, 0.13)),
    "brow_L": ((0.4, -0.86, 0.55), (0.26, 0.07, 0.05)),
    "brow_R": ((-0.4, -0.86, 0.55), (0.26, 0.07, 0.05)),
    "mouth": ((0.0, -0.9, -0.5), (0.34, 0.12, 0.07)),
}


def _shape(name: str, co: np.ndarray, part: dict[str, slice]) -> np.ndarray:
    """The vertex positions of one ARKit shape key."""
    out = co.copy()
    side = "L" if name.endswith("Left") else "R"
    if name == "jawOpen":
        m = out[part["mouth"]]
        lower = m[:, 2] < -0.5
        m[lower, 2] -= 0.3 * (1 - np.abs(m[lower, 0]) / 0.34) ** 0.5  # the lower lip drops, most at the middle
    elif name.startswith("mouthStretch"):
        m = out[part["mouth"]]
        sel = m[:, 0] > 0 if side == "L" else m[:, 0] < 0
        m[sel, 0] *= 2.0
        m[sel, 2] -= 0.15 * np.abs(m[sel, 0])
    elif name.startswith("eyeSquint"):
        e = out[part[f"eye_{side}"]]
        e[:, 2] = 0.25 + (e[:, 2] - 0.25) * 0.1 - 0.03
    elif name.startswith("browDown"):
        b = out[part[f"brow_{side}"]]
        b[:, 2] -= 0.25 + 0.3 * (0.66 - np.abs(b[:, 0]))  # down, the inner end most
    return out


def make_face(name: str = "Face") -> bpy.types.Object:
    """A head mesh with a Basis and the seven :data:`ARKIT_KEYS` shape keys, linked to the scene."""
    verts, faces, part = [], [], {}
    for pname, (center, radii) in PARTS.items():
        v, f = _ellipsoid(center, radii)
        start = sum(len(x) for x in verts)
        part[pname] = slice(start, start + len(v))
        faces += [tuple(i + start for i in face) for face in f]
        verts.append(v)
    co = np.concatenate(verts)
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata(co.tolist(), [], faces)
    mesh.shade_smooth() if hasattr(mesh, "shade_smooth") else None
    ob = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(ob)
    ob.shape_key_add(name="Basis")
    for key in ARKIT_KEYS:
        block = ob.shape_key_add(name=key, from_mix=False)
        block.data.foreach_set("co", _shape(key, co, part).astype(np.float32).ravel())
    return ob


def ensure_addon() -> str:
    """Use the installed add-on, or register it from the ``effortface`` package; say which."""
    if hasattr(bpy.types.Scene, "effortface"):
        return "installed extension"
    from effortface.blender import register

    register()
    return "registered from the effortface package"


def clear_scene() -> None:
    """Remove every object (the startup cube, camera and light)."""
    for ob in list(bpy.data.objects):
        bpy.data.objects.remove(ob)


def build_scene(bvh: Path = SAMPLE_BVH, seconds: float | None = None) -> tuple[bpy.types.Object, bpy.types.Object]:
    """Import ``bvh`` (Blender's importer: the scene takes its rate and duration; ``seconds`` keeps
    the first seconds), add the face beside it, select both with the armature active; (armature, face)."""
    clear_scene()
    bpy.ops.import_anim.bvh(filepath=str(bvh), update_scene_fps=True, update_scene_duration=True)
    scene = bpy.context.scene
    armature = bpy.context.active_object
    if seconds is not None:
        fps = scene.render.fps / scene.render.fps_base
        scene.frame_end = min(scene.frame_end, scene.frame_start + int(round(seconds * fps)) - 1)
    face = make_face()
    face.location = (3.0, 0.0, 1.5)
    select(armature, face)
    return armature, face


def select(active: bpy.types.Object, *others: bpy.types.Object) -> None:
    """Select ``active`` (made the active object) and ``others``, nothing else."""
    keep = {active.name, *(o.name for o in others)}
    bpy.context.view_layer.update()  # objects linked since the last update get their view-layer bases
    for ob in bpy.context.view_layer.objects:
        ob.select_set(ob.name in keep)
    bpy.context.view_layer.objects.active = active


def render_face(face: bpy.types.Object, frame: int, path: Path, size: int = 320) -> Path:
    """Render the face alone at ``frame`` (Workbench, ``size`` pixels square) to ``path``."""
    scene = bpy.context.scene
    scene.frame_set(frame)
    cam_data = bpy.data.cameras.get("FaceCam") or bpy.data.cameras.new("FaceCam")
    cam = bpy.data.objects.get("FaceCam") or bpy.data.objects.new("FaceCam", cam_data)
    if cam.name not in scene.collection.objects:
        scene.collection.objects.link(cam)
    cam.location = (face.location.x, face.location.y - 6.0, face.location.z)
    cam.rotation_euler = (np.pi / 2, 0.0, 0.0)
    cam_data.lens = 70
    scene.camera = cam
    for ob in scene.objects:
        ob.hide_render = ob not in (face, cam)
    scene.render.engine = "BLENDER_WORKBENCH"
    scene.display.shading.light = "STUDIO"
    scene.display.shading.color_type = "SINGLE"
    scene.display.shading.single_color = (0.85, 0.62, 0.5)
    scene.render.resolution_x = scene.render.resolution_y = size
    scene.render.resolution_percentage = 100
    scene.render.filepath = str(path)
    bpy.ops.render.render(write_still=True)
    return path


def main(argv: list[str] | None = None) -> int:
    """Build the demo scene, bake, optionally render; print one line per step."""
    argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else (argv if argv is not None else sys.argv[1:])
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bvh", type=Path, default=SAMPLE_BVH)
    parser.add_argument("--seconds", type=float, default=None, help="keep the first seconds of the clip")
    parser.add_argument("--render", type=Path, default=None, metavar="DIR")
    args = parser.parse_args(argv)
    print(f"add-on: {ensure_addon()}")
    armature, face = build_scene(args.bvh, args.seconds)
    result = bpy.ops.effortface.bake_face()
    print(f"bake: {result}")
    if args.render is not None:
        fcurves = face.data.shape_keys.animation_data.action.fcurves
        points = [fcurves.find(f'key_blocks["{key}"].value').keyframe_points for key in ARKIT_KEYS]
        total = np.sum([[k.co[1] for k in p] for p in points], axis=0)
        peak = int(points[0][int(np.argmax(total))].co[0])  # the frame of the strongest face
        face.data.shape_keys.animation_data_clear()  # the rest face: every key at 0
        render_face(face, peak, args.render / "blender_face_before.png")
        bpy.ops.ed.undo_push()
        result = bpy.ops.effortface.bake_face()
        render_face(face, peak, args.render / "blender_face_after.png")
        weights = ", ".join(f"{k} {face.data.shape_keys.key_blocks[k].value:.2f}" for k in ARKIT_KEYS)
        face.data.shape_keys.animation_data_clear()
        for key in ARKIT_KEYS:
            face.data.shape_keys.key_blocks[key].value = 1.0
        render_face(face, peak, args.render / "blender_face_keys_at_1.png")  # what the keys do
        print(f"rendered frame {peak} ({weights}) to {args.render}")
    return 0


if __name__ == "__main__":
    code = main()
    sys.stdout.flush()
    import os

    os._exit(code)  # the bpy module can hang at interpreter exit after rendering
