"""The add-on's work that needs no Blender: an armature's posed bones as a :class:`Motion`, the
curves of a bake, the shape-key mapping table and curve files keyed back.

Imports the numpy runtime only (no ``bpy``), so the command line and the tests use it as they
are; inside Blender the add-on (:mod:`effortface.blender.ui`) feeds it the bones Blender evaluated.

Joints: every bone's head is a joint named like the bone; a bone without children adds its tail as
``<bone>_end``, as :func:`effortface.synth.motion.read_bvh` names a BVH end site (Blender's BVH
importer puts a leaf bone's tail on its End Site). The skeleton conventions and ``--mapping`` JSON of
the command line (:mod:`effortface.synth.segments`) then find the segments.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from effortface.core.blendshapes import BlendshapeSet
from effortface.core.errors import UserError
from effortface.synth.motion import Motion, detect_bvh_unit_m, motion_from_positions
from effortface.synth.runtime import Character, FaceModel

#: the curves stored as custom properties (with F-curves) on the armature, for other drivers
PROPERTY_CURVES = ("w_per_kg", "p_per_kg", "hr_bpm", "epoc")
#: prefix of those custom properties (``effortface_hr_bpm`` ...)
PROPERTY_PREFIX = "effortface_"


@dataclasses.dataclass(frozen=True)
class Skeleton:
    """Joints of an armature: its bones' heads, then the tails of bones without children.

    Attributes
    ----------
    joint_names : tuple of str
        Bone names, then ``<bone>_end`` for every leaf bone.
    parents : tuple of int
        Parent joint of each joint (-1 for a root bone).
    n_bones : int
        Bones (the first ``n_bones`` joints are heads).
    leaves : tuple of int
        Bone index of every ``_end`` joint, in order.
    """

    joint_names: tuple[str, ...]
    parents: tuple[int, ...]
    n_bones: int
    leaves: tuple[int, ...]


def skeleton_from_bones(names: Sequence[str], parent_names: Sequence[str | None]) -> Skeleton:
    """The joints of bones given in Blender's order (a parent before its children).

    Parameters
    ----------
    names : sequence of str
        Bone names.
    parent_names : sequence of str or None
        Each bone's parent name (None for a root).

    Returns
    -------
    Skeleton
    """
    index = {n: i for i, n in enumerate(names)}
    parents = [index[p] if p is not None else -1 for p in parent_names]
    has_child = set(parents)
    leaves = tuple(i for i in range(len(names)) if i not in has_child)
    return Skeleton(tuple(names) + tuple(f"{names[i]}_end" for i in leaves),
                    tuple(parents) + leaves, len(names), leaves)


def joint_positions(skeleton: Skeleton, matrices_t: np.ndarray, lengths: np.ndarray,
                    world: np.ndarray) -> np.ndarray:
    """World positions of the joints from posed bone matrices.

    Parameters
    ----------
    skeleton : Skeleton
    matrices_t : ndarray, shape (T, n_bones, 4, 4)
        Every frame's pose-bone matrices (armature space) as Blender's ``foreach_get("matrix")``
        gives them: column-major, so ``matrices_t[t, b]`` is the transposed matrix (row 3 the head,
        row 1 the bone's Y axis).
    lengths : ndarray, shape (n_bones,)
        Bone lengths (head to tail), armature units.
    world : ndarray, shape (T, 4, 4)
        The armature object's world matrix per frame.

    Returns
    -------
    ndarray, shape (T, J, 3)
        Positions in scene units (Blender's Z up).
    """
    heads = matrices_t[:, :, 3, :3]
    tails = heads[:, list(skeleton.leaves)] + matrices_t[:, list(skeleton.leaves), 1, :3] \
        * np.asarray(lengths, float)[list(skeleton.leaves), None]
    local = np.concatenate([heads, tails], axis=1)
    return np.einsum("tij,tkj->tki", world[:, :3, :3], local) + world[:, None, :3, 3]


def joint_rotations(skeleton: Skeleton, matrices_t: np.ndarray, world: np.ndarray) -> np.ndarray:
    """World rotations of the joints (T, J, 3, 3), columns the frame's axes: each bone's posed
    frame, an ``_end`` joint its bone's (as the BVH reader gives an end site its parent's).

    A bone's frame differs from the BVH joint's by a constant rest rotation, which leaves the
    angular velocity the energies take from consecutive rotations (``log(R(k) R(k-1)^T)``)
    unchanged; without rotations, spin about a segment's long axis would not be seen.
    """
    bones = np.swapaxes(matrices_t[:, :, :3, :3], -1, -2)  # back to row-major: M[:3, :3]
    rot = np.einsum("tij,tbjk->tbik", world[:, :3, :3], bones)
    rot /= np.linalg.norm(rot, axis=-2, keepdims=True)  # no object or bone scale
    return np.concatenate([rot, rot[:, list(skeleton.leaves)]], axis=1)


def rest_height(heads: np.ndarray, tails: np.ndarray, skeleton: Skeleton) -> float:
    """Height (along Z) of the rest pose: bone heads and the leaf bones' tails, armature units."""
    z = np.concatenate([np.asarray(heads, float)[:, 2], np.asarray(tails, float)[list(skeleton.leaves), 2]])
    return float(z.max() - z.min())


def unit_m(height_units: float, unit_m: float = 0.0) -> float:
    """Metres per scene unit: ``unit_m`` when above 0, else detected from the rest-pose height as
    ``effortface synth`` detects a BVH file's unit (:func:`effortface.synth.motion.detect_bvh_unit_m`:
    metre, CMU's 0.05644 m, inch, centimetre, millimetre)."""
    if unit_m > 0:
        return float(unit_m)
    return detect_bvh_unit_m(height_units)[1]


def motion_of(skeleton: Skeleton, positions_units: np.ndarray, rotations: np.ndarray | None,
              metres_per_unit: float, fps: float, source: str) -> Motion:
    """The bake's :class:`Motion` (metres, Z up: Blender's axes are already effortface's; a
    turn about Z between Blender's BVH axes and effortface's changes no energy)."""
    motion = motion_from_positions(np.asarray(positions_units, float) * metres_per_unit,
                                   skeleton.joint_names, skeleton.parents, fps, source=source)
    return motion if rotations is None else dataclasses.replace(motion, rotations=np.asarray(rotations, float))


def bake_curves(model: FaceModel, motion: Motion, character: Character, mapping: Any = None
                ) -> dict[str, np.ndarray]:
    """Per-frame curves of the runtime (:meth:`FaceModel.synthesize`) for the sampled motion."""
    return model.synthesize(motion, character, mapping=mapping)


def default_rows(blendshapes: BlendshapeSet) -> list[tuple[str, str]]:
    """The mapping table's default rows ``(blendshape, shape key)``: every ARKit name of each
    blendshape (:data:`effortface.core.blendshapes.DEFAULT_SET`, the names the Live Link export
    writes), then the blendshape's own name."""
    rows = [(shape.name, arkit) for shape in blendshapes.shapes for arkit in shape.arkit]
    return rows + [(shape.name, shape.name) for shape in blendshapes.shapes]


def key_targets(rows: Iterable[tuple[str, str]], shape_keys: Iterable[str],
                columns: Iterable[str]) -> dict[str, str]:
    """Shape key -> curve column to key on it.

    A shape key named like a column takes that column (an ARKit column of a Live Link file, a
    blendshape of a per-frame CSV); otherwise the first mapping row naming the shape key gives
    its blendshape, when that is a column.
    """
    cols = set(columns)
    table: dict[str, str] = {}
    for blendshape, key in rows:
        table.setdefault(key, blendshape)
    out = {}
    for key in shape_keys:
        if key in cols:
            out[key] = key
        elif table.get(key) in cols:
            out[key] = table[key]
    return out


def describe_targets(rows: Iterable[tuple[str, str]]) -> str:
    """The shape-key names a mapping table looks for, for an error line."""
    return ", ".join(dict.fromkeys(key for _, key in rows))


def frame_range(scene_range: tuple[int, int], action_range: tuple[float, float]) -> tuple[int, int]:
    """The frames to bake: the scene's range within the action's keyed range (Blender's BVH
    importer ends the scene one frame after the file's last frame).

    Raises
    ------
    UserError
        If fewer than two frames are left.
    """
    first = max(scene_range[0], int(np.ceil(action_range[0] - 1e-6)))
    last = min(scene_range[1], int(np.floor(action_range[1] + 1e-6)))
    if last - first < 1:
        raise UserError(f"frame range: expected at least two frames of the action "
                        f"({action_range[0]:g}-{action_range[1]:g}) in the scene's range "
                        f"{scene_range[0]}-{scene_range[1]}, found {max(last - first + 1, 0)}")
    return first, last


def keys_of(curve: np.ndarray, first_frame: float, frames_per_sample: float = 1.0) -> np.ndarray:
    """Interleaved ``frame, value`` pairs (Blender's ``keyframe_points.foreach_set("co", ...)``)."""
    values = np.asarray(curve, float)
    frames = first_frame + np.arange(len(values)) * frames_per_sample
    return np.column_stack([frames, values]).ravel()


def check_mapping_path(path: str) -> Path | None:
    """The skeleton mapping file of the panel (None when empty); a missing file is a UserError."""
    if not path.strip():
        return None
    p = Path(path)
    if not p.is_file():
        raise UserError(f"mapping {p}: expected a JSON mapping file, found no such file")
    return p


def curves_frames(t_s: np.ndarray, fps: float, first_frame: int) -> np.ndarray:
    """Scene frames of curve-file times (frame ``first_frame`` at t = 0)."""
    return first_frame + np.asarray(t_s, float) * fps


def columns_for_keys(curves: Mapping[str, np.ndarray]) -> list[str]:
    """The columns of a curve file that may go onto shape keys (all but the time)."""
    return [c for c in curves if c != "t_s"]
