"""The add-on inside Blender: settings, the N-panel and the operators ``effortface.bake_face`` and
``effortface.import_curves`` (imports ``bpy``: only Blender loads this module).

The work that needs no Blender is :mod:`effortface.blender.bake`. A wrong selection or a bad file is
one line in Blender's report (``self.report({'ERROR'}, ...)``) and nothing is keyed: every check and
the whole synthesis happen before the first key is written.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import bpy
import numpy as np

from . import bake
from effortface.core.blendshapes import DEFAULT_SET
from effortface.core.errors import UserError
from effortface.core.participant import LIMITS
from effortface.synth.runtime import Character, load_model
from effortface.synth.segments import SegmentMappingError
from effortface.synth.curves_io import read_curves

_SEXES = [("male", "Male", "de Leva male table"), ("female", "Female", "de Leva female table")]


def _limit(limit: str, **kw: Any) -> Any:
    """A FloatProperty bounded by the participant limits every stage reads."""
    lo, hi = LIMITS[limit].bounds
    return bpy.props.FloatProperty(min=lo, max=hi, description=LIMITS[limit].meaning, **kw)


class EFFORTFACE_PG_row(bpy.types.PropertyGroup):
    """One row of the mapping table: an effortface blendshape onto a shape key."""

    blendshape: bpy.props.StringProperty(name="Blendshape")  # type: ignore[valid-type]
    shape_key: bpy.props.StringProperty(name="Shape key")  # type: ignore[valid-type]


class EFFORTFACE_PG_settings(bpy.types.PropertyGroup):
    """The scene's effortface settings (``scene.effortface``)."""

    model: bpy.props.StringProperty(  # type: ignore[valid-type]
        name="Model", default="default", subtype="DIR_PATH",
        description="'default' (the rule model), 'paper-2015', or a bundle folder of effortface train")
    age: _limit("age", name="Age", default=30.0)  # type: ignore[valid-type]
    sex: bpy.props.EnumProperty(name="Sex", items=_SEXES, default="male")  # type: ignore[valid-type]
    height_m: _limit("height_m", name="Height (m)", default=1.78)  # type: ignore[valid-type]
    mass_kg: _limit("mass_kg", name="Mass (kg)", default=75.0)  # type: ignore[valid-type]
    training_level: _limit("training_level", name="Training level", default=5.0)  # type: ignore[valid-type]
    mapping_path: bpy.props.StringProperty(  # type: ignore[valid-type]
        name="Skeleton mapping", subtype="FILE_PATH",
        description="JSON segment -> [proximal, distal] joints, as effortface synth --mapping "
                    "(empty: the built-in conventions)")
    unit_m: bpy.props.FloatProperty(  # type: ignore[valid-type]
        name="Unit (m)", default=0.0, min=0.0, precision=5,
        description="metres per scene unit (0: detected from the rest pose, as effortface synth does for BVH)")
    rows: bpy.props.CollectionProperty(type=EFFORTFACE_PG_row)  # type: ignore[valid-type]
    curves_path: bpy.props.StringProperty(  # type: ignore[valid-type]
        name="Curves file", subtype="FILE_PATH",
        description="a CSV or Live Link Face CSV written by effortface synth")


def settings(context: Any) -> Any:
    """The scene's settings, its mapping table filled with the defaults when empty."""
    s = context.scene.effortface
    if not len(s.rows):
        for blendshape, key in bake.default_rows(DEFAULT_SET):
            row = s.rows.add()
            row.blendshape, row.shape_key = blendshape, key
    return s


def _rows(s: Any) -> list[tuple[str, str]]:
    return [(r.blendshape, r.shape_key) for r in s.rows]


def _targets(context: Any, rows: list[tuple[str, str]], columns: list[str]) -> list[tuple[Any, dict[str, str]]]:
    """(mesh object, shape key -> column) of every selected mesh with matching shape keys.

    Raises
    ------
    UserError
        When no selected mesh has one.
    """
    meshes = [o for o in context.selected_objects if o.type == "MESH"]
    out = []
    for ob in meshes:
        keys = ob.data.shape_keys
        names = [k.name for k in keys.key_blocks] if keys else []
        found = bake.key_targets(rows, names, columns)
        if found:
            out.append((ob, found))
    if not out:
        have = ", ".join(o.name for o in meshes) or "no selected mesh"
        raise UserError(f"expected selected meshes with shape keys named {bake.describe_targets(rows)}, "
                        f"found {have} without them")
    return out


def _fcurve(id_data: Any, data_path: str, keys: np.ndarray) -> None:
    """Replace the F-curve ``data_path`` of ``id_data`` by linear keys (interleaved frame, value)."""
    anim = id_data.animation_data or id_data.animation_data_create()
    if anim.action is None:
        anim.action = bpy.data.actions.new(f"{id_data.name}_effortface")
    old = anim.action.fcurves.find(data_path)
    if old is not None:
        anim.action.fcurves.remove(old)
    id_data.keyframe_insert(data_path, frame=float(keys[0]))  # a slot and channel bag as Blender makes them
    fc = anim.action.fcurves.find(data_path)
    fc.keyframe_points.clear()
    fc.keyframe_points.add(len(keys) // 2)
    fc.keyframe_points.foreach_set("co", keys.astype(np.float32))
    fc.keyframe_points.foreach_set("interpolation", np.full(len(keys) // 2, 1, np.int8))  # LINEAR
    fc.update()


def key_curves(targets: list[tuple[Any, dict[str, str]]], curves: dict[str, np.ndarray],
               frames: np.ndarray) -> int:
    """Key every target shape key with its column at ``frames``; the number of shape keys keyed."""
    n = 0
    for ob, found in targets:
        for key, column in found.items():
            keys = np.column_stack([frames, curves[column]]).ravel()
            _fcurve(ob.data.shape_keys, f'key_blocks["{key}"].value', keys)
            n += 1
    return n


def sample_armature(context: Any, ob: Any, first: int, last: int
                    ) -> tuple[bake.Skeleton, np.ndarray, np.ndarray, float]:
    """Blender's own evaluation of the armature at every frame: (skeleton, positions in scene
    units (T, J, 3), world rotations (T, J, 3, 3), rest-pose height in scene units)."""
    scene = context.scene
    bones = ob.data.bones
    skeleton = bake.skeleton_from_bones([b.name for b in bones],
                                        [b.parent.name if b.parent else None for b in bones])
    n = len(bones)
    lengths = np.array([b.length for b in bones])
    mats = np.empty((last - first + 1, n, 4, 4), np.float32)
    world = np.empty((last - first + 1, 4, 4))
    buf = np.empty(n * 16, np.float32)
    pose_bones = ob.pose.bones
    current = scene.frame_current
    moves = _object_moves(ob)
    try:
        for k, frame in enumerate(range(first, last + 1)):
            scene.frame_set(frame)
            pose_bones.foreach_get("matrix", buf)
            mats[k] = buf.reshape(n, 4, 4)
            if moves or not k:
                world[k] = np.array(ob.matrix_world)
        if not moves:
            world[1:] = world[0]
    finally:
        scene.frame_set(current)
    heads = np.array([ob.matrix_world @ b.head_local for b in bones])
    tails = np.array([ob.matrix_world @ b.tail_local for b in bones])
    positions = bake.joint_positions(skeleton, mats, lengths, world)  # float32 in (as Blender poses), float64 out
    rotations = bake.joint_rotations(skeleton, mats, world)
    return skeleton, positions, rotations, bake.rest_height(heads, tails, skeleton)


#: an object's own transform channels (its bones' are read from the pose every frame)
_TRANSFORMS = ("location", "rotation_euler", "rotation_quaternion", "rotation_axis_angle", "scale",
               "delta_location", "delta_rotation_euler", "delta_rotation_quaternion", "delta_scale")


def _object_moves(ob: Any) -> bool:
    """Whether the armature object's own world matrix may change over frames (a parent, a
    constraint, a driver or a keyed transform); if not it is read once."""
    anim = ob.animation_data
    keyed = anim is not None and ((anim.action is not None and any(
        fc.data_path in _TRANSFORMS for fc in anim.action.fcurves)) or len(anim.drivers) > 0
        or len(anim.nla_tracks) > 0)
    return ob.parent is not None or len(ob.constraints) > 0 or keyed


def scene_fps(scene: Any) -> float:
    """The scene's frame rate (fps / fps_base)."""
    return float(scene.render.fps / scene.render.fps_base)


class EFFORTFACE_OT_bake_face(bpy.types.Operator):
    """Key the effort face of the active armature's action onto the selected meshes' shape keys"""

    bl_idname = "effortface.bake_face"
    bl_label = "Bake effort face"
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context: Any) -> set[str]:
        try:
            done = bake_face(context)
        except UserError as exc:
            self.report({"ERROR"}, f"Bake effort face: {exc}")
            return {"CANCELLED"}
        self.report({"INFO"}, done)
        return {"FINISHED"}


def _armature(context: Any) -> tuple[Any, Any]:
    ob = context.active_object
    if ob is None or ob.type != "ARMATURE":
        found = "no active object" if ob is None else f"{ob.name} ({ob.type.lower()})"
        raise UserError(f"expected an active armature, found {found}")
    action = ob.animation_data.action if ob.animation_data else None
    if action is None:
        raise UserError(f"expected an armature with an action, found {ob.name} without one")
    return ob, action


def bake_face(context: Any) -> str:
    """The operator's work: check, sample, synthesize, then key; a one-line summary."""
    s = settings(context)
    ob, action = _armature(context)
    model = load_model(s.model.strip() or "default")
    targets = _targets(context, _rows(s), list(model.blendshapes.names))
    character = Character(age=s.age, sex=s.sex, height_m=s.height_m, mass_kg=s.mass_kg,
                          training_level=s.training_level,
                          expressiveness=(1.0,) * len(model.blendshapes))
    scene = context.scene
    first, last = bake.frame_range((scene.frame_start, scene.frame_end), tuple(action.frame_range))
    skeleton, positions, rotations, height = sample_armature(context, ob, first, last)
    metres = bake.unit_m(height, s.unit_m)
    motion = bake.motion_of(skeleton, positions, rotations, metres, scene_fps(scene), f"{ob.name} ({action.name})")
    try:
        curves = bake.bake_curves(model, motion, character, bake.check_mapping_path(bpy.path.abspath(s.mapping_path)))
    except SegmentMappingError as exc:
        raise UserError(f"{exc} (here: the panel's Skeleton mapping field)") from None
    frames = np.arange(first, last + 1, dtype=float)
    n = key_curves(targets, curves, frames)
    for name in bake.PROPERTY_CURVES:
        prop = bake.PROPERTY_PREFIX + name
        ob[prop] = float(curves[name][0])
        _fcurve(ob, f'["{prop}"]', np.column_stack([frames, curves[name]]).ravel())
    return (f"effort face: {n} shape keys keyed over frames {first}-{last} "
            f"({motion.n_frames / motion.fps:.1f} s at {motion.fps:g} fps, {metres:g} m per unit)")


class EFFORTFACE_OT_import_curves(bpy.types.Operator):
    """Key a CSV or Live Link Face CSV written by effortface synth onto the selected meshes' shape keys"""

    bl_idname = "effortface.import_curves"
    bl_label = "Import curves"
    bl_options = {"REGISTER", "UNDO"}

    filepath: bpy.props.StringProperty(subtype="FILE_PATH")  # type: ignore[valid-type]

    def execute(self, context: Any) -> set[str]:
        s = settings(context)
        path = bpy.path.abspath(self.filepath or s.curves_path)
        try:
            if not path:
                raise UserError("expected a curves file (the panel's Curves file), found none")
            curves = read_curves(path)
            targets = _targets(context, _rows(s), bake.columns_for_keys(curves))
            frames = bake.curves_frames(curves["t_s"], scene_fps(context.scene), context.scene.frame_start)
            n = key_curves(targets, curves, frames)
        except UserError as exc:
            self.report({"ERROR"}, f"Import curves: {exc}")
            return {"CANCELLED"}
        self.report({"INFO"}, f"{Path(path).name}: {n} shape keys keyed, {len(frames)} rows")
        return {"FINISHED"}

    def invoke(self, context: Any, event: Any) -> set[str]:
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}


class EFFORTFACE_OT_reset_mapping(bpy.types.Operator):
    """Put the mapping table back to the ARKit names and effortface's own"""

    bl_idname = "effortface.reset_mapping"
    bl_label = "Reset mapping"

    def execute(self, context: Any) -> set[str]:
        context.scene.effortface.rows.clear()
        settings(context)
        return {"FINISHED"}


class EFFORTFACE_OT_add_row(bpy.types.Operator):
    """Add a row to the mapping table"""

    bl_idname = "effortface.add_row"
    bl_label = "Add mapping row"

    def execute(self, context: Any) -> set[str]:
        row = settings(context).rows.add()
        row.blendshape = DEFAULT_SET.names[0]
        return {"FINISHED"}


class EFFORTFACE_PT_panel(bpy.types.Panel):
    """The N-panel: character, model, skeleton, mapping table, bake and import."""

    bl_label = "Effort face"
    bl_idname = "EFFORTFACE_PT_panel"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Effort"

    def draw(self, context: Any) -> None:
        s = context.scene.effortface
        layout = self.layout
        col = layout.column(align=True)
        for name in ("age", "sex", "height_m", "mass_kg", "training_level"):
            col.prop(s, name)
        layout.prop(s, "model")
        layout.prop(s, "mapping_path")
        layout.prop(s, "unit_m")
        box = layout.box()
        box.label(text="Blendshape -> shape key")
        for row in s.rows:
            line = box.row(align=True)
            line.prop(row, "blendshape", text="")
            line.prop(row, "shape_key", text="")
        line = box.row(align=True)
        line.operator("effortface.add_row", text="Add")
        line.operator("effortface.reset_mapping", text="Reset")
        layout.operator("effortface.bake_face")
        layout.prop(s, "curves_path")
        layout.operator("effortface.import_curves").filepath = s.curves_path


CLASSES = (EFFORTFACE_PG_row, EFFORTFACE_PG_settings, EFFORTFACE_OT_bake_face, EFFORTFACE_OT_import_curves,
           EFFORTFACE_OT_reset_mapping, EFFORTFACE_OT_add_row, EFFORTFACE_PT_panel)


def register() -> None:
    """Register the classes and ``Scene.effortface``."""
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Scene.effortface = bpy.props.PointerProperty(type=EFFORTFACE_PG_settings)


def unregister() -> None:
    """Undo :func:`register`."""
    del bpy.types.Scene.effortface
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
