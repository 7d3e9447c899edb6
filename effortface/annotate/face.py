"""The parametric face drawn from the four blendshape weights (numpy + OpenCV, no Qt).

A cartoon face in which each blendshape of the paper's set reads at a glance:

- ``mouth_stretch``: the mouth corners are pulled wider and slightly down, the lips thin out;
- ``mouth_open``: the jaw drops (the mouth opens on dark inside and teeth, the chin goes down);
- ``eye_squint``: the lids close towards a slit and crow's-feet lines appear;
- ``brow_lower``: the brows come down and in, tilted inwards, with frown lines between them.

Used to render the sample videos and as the annotator's preview. The face is drawn in a
normalised frame (origin at the face centre, unit = half the face height, y down), transformed by
the head pose, rasterised at a supersampled size and shrunk with area averaging (anti-aliasing
that stays sharp at 160x120).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence

import numpy as np

from effortface.core.blendshapes import DEFAULT_SET, BlendshapeSet

#: default skin colour (BGR)
SKIN_BGR = (150, 180, 225)
#: default hair and brow colour (BGR)
HAIR_BGR = (40, 55, 75)
_BACKGROUND_BGR = (120, 110, 100)
_LINE_BGR = (50, 60, 90)
_SUPERSAMPLE_MIN_PX = 480  # rasterise at least this wide, then shrink

BGR = tuple[int, int, int]
#: maps normalised face points (N, 2) to integer pixel coordinates (N, 2)
ToPx = Callable[[np.ndarray], np.ndarray]


def face_weights(weights: Mapping[str, float] | Sequence[float] | np.ndarray,
                 blendshapes: BlendshapeSet = DEFAULT_SET) -> dict[str, float]:
    """Normalise ``weights`` (a dict by name or a vector in set order) to a dict clipped to [0, 1].

    Raises
    ------
    ValueError
        If a vector has the wrong length or a name is not a blendshape of the set.
    """
    if isinstance(weights, Mapping):
        unknown = set(weights) - set(blendshapes.names)
        if unknown:
            raise ValueError(f"weights: expected names among {blendshapes.names}, found {sorted(unknown)}")
        values = {n: float(weights.get(n, 0.0)) for n in blendshapes.names}
    else:
        vec = np.asarray(weights, dtype=float).ravel()
        if vec.size != len(blendshapes):
            raise ValueError(f"weights: expected {len(blendshapes)} values, found {vec.size}")
        values = dict(zip(blendshapes.names, vec.tolist()))
    return {n: float(np.clip(np.nan_to_num(v), 0.0, 1.0)) for n, v in values.items()}


def render_face(
    weights: Mapping[str, float] | Sequence[float] | np.ndarray,
    size: tuple[int, int] = (320, 240),
    *,
    head_pose: tuple[float, float, float] = (0.0, 0.0, 0.0),
    lighting: float = 1.0,
    skin: BGR = SKIN_BGR,
    hair: BGR = HAIR_BGR,
    rng: np.random.Generator | None = None,
    noise_sd: float = 2.0,
) -> np.ndarray:
    """Draw the face for four blendshape weights.

    Parameters
    ----------
    weights : dict or array-like
        ``mouth_stretch``, ``mouth_open``, ``eye_squint``, ``brow_lower`` in [0, 1] (a dict by name,
        missing names are 0, or a vector in the default set's order).
    size : (int, int)
        Output width and height in pixels.
    head_pose : (float, float, float)
        Head shift ``dx, dy`` as a fraction of the image width / height, and roll in degrees.
    lighting : float
        Overall brightness factor (1 = nominal); a left-right light gradient follows it.
    skin : (int, int, int)
        Skin colour, BGR.
    hair : (int, int, int)
        Hair and brow colour, BGR.
    rng : numpy.random.Generator, optional
        When given, adds Gaussian sensor noise of ``noise_sd`` grey levels (deterministic per rng).
    noise_sd : float
        Sensor-noise standard deviation in grey levels (used only with ``rng``).

    Returns
    -------
    numpy.ndarray
        BGR uint8 image of shape ``(height, width, 3)``.
    """
    from effortface.core.opencv import import_cv2

    cv2 = import_cv2()

    w_px, h_px = int(size[0]), int(size[1])
    if w_px < 16 or h_px < 16:
        raise ValueError(f"size: expected at least 16x16 pixels, found {w_px}x{h_px}")
    wt = face_weights(weights)
    ss = max(1, math.ceil(_SUPERSAMPLE_MIN_PX / w_px))
    canvas = np.empty((h_px * ss, w_px * ss, 3), np.uint8)
    canvas[:] = _BACKGROUND_BGR
    to_px = _pose_transform(w_px * ss, h_px * ss, head_pose)
    _draw_head(canvas, to_px, wt, skin, hair)
    _draw_eyes(canvas, to_px, wt, ss)
    _draw_brows(canvas, to_px, wt, hair, ss)
    _draw_nose(canvas, to_px, ss)
    _draw_mouth(canvas, to_px, wt, ss)
    img = cv2.resize(canvas, (w_px, h_px), interpolation=cv2.INTER_AREA)
    return _light(img, lighting, rng, noise_sd)


def _pose_transform(w_px: int, h_px: int, head_pose: tuple[float, float, float]) -> ToPx:
    """Map normalised face points (N, 2) to pixel coordinates under the head pose."""
    dx, dy, roll_deg = head_pose
    scale = 0.42 * h_px  # half face height in pixels
    centre = np.array([w_px * (0.5 + dx), h_px * (0.5 + dy)])
    c, s = math.cos(math.radians(roll_deg)), math.sin(math.radians(roll_deg))
    rot = np.array([[c, -s], [s, c]]) * scale

    def to_px(points: np.ndarray) -> np.ndarray:
        pts = np.asarray(points, dtype=float).reshape(-1, 2)
        return np.round(pts @ rot.T + centre).astype(np.int32)

    return to_px


def _ellipse(cx: float, cy: float, rx: float, ry: float, n: int = 48,
             t0: float = 0.0, t1: float = 2 * math.pi) -> np.ndarray:
    """Points on an ellipse arc (normalised coordinates)."""
    t = np.linspace(t0, t1, n)
    return np.column_stack([cx + rx * np.cos(t), cy + ry * np.sin(t)])


def _fill(canvas: np.ndarray, to_px: ToPx, pts: np.ndarray, colour: BGR) -> None:
    """Fill the polygon ``pts`` (normalised coordinates), anti-aliased."""
    from effortface.core.opencv import import_cv2

    cv2 = import_cv2()

    cv2.fillPoly(canvas, [to_px(pts)], colour, lineType=cv2.LINE_AA)


def _line(canvas: np.ndarray, to_px: ToPx, pts: np.ndarray, colour: BGR, thick: float, ss: int) -> None:
    """Open polyline of ``thick`` output pixels (scaled by the supersampling ``ss``)."""
    from effortface.core.opencv import import_cv2

    cv2 = import_cv2()

    cv2.polylines(canvas, [to_px(pts)], False, colour, max(1, round(thick * ss)), cv2.LINE_AA)


def _shade(colour: BGR, factor: float) -> BGR:
    """A darker (factor < 1) version of a colour."""
    b, g, r = (int(c * factor) for c in colour)
    return (b, g, r)


def _draw_head(canvas: np.ndarray, to_px: ToPx, wt: dict[str, float], skin: BGR, hair: BGR) -> None:
    """Hair, ears, neck and the face oval; the chin follows the jaw drop."""
    jaw = 0.12 * wt["mouth_open"]
    _fill(canvas, to_px, np.array([[-0.28, 0.7], [0.28, 0.7], [0.34, 1.4], [-0.34, 1.4]]),
          _shade(skin, 0.85))
    for side in (-1, 1):
        _fill(canvas, to_px, _ellipse(side * 0.72, 0.02, 0.1, 0.17), _shade(skin, 0.9))
    _fill(canvas, to_px, _ellipse(0, -0.12, 0.8, 0.9), hair)
    upper = _ellipse(0, 0, 0.7, 0.9, 40, math.pi, 2 * math.pi)
    lower = _ellipse(0, 0, 0.7, 0.9 + jaw, 40, 0, math.pi)
    _fill(canvas, to_px, np.vstack([lower, upper]), skin)
    _fill(canvas, to_px, _ellipse(0, -0.78, 0.62, 0.2, 40, math.pi, 2 * math.pi), hair)


def _draw_eyes(canvas: np.ndarray, to_px: ToPx, wt: dict[str, float], ss: int) -> None:
    """Almond eyes whose lids close with ``eye_squint``; crow's feet above 0.3."""
    squint = wt["eye_squint"]
    open_frac = 1.0 - 0.88 * squint
    for side in (-1, 1):
        cx, cy = side * 0.3, -0.12 + 0.02 * squint
        rx, ry_up, ry_lo = 0.15, 0.1 * open_frac, 0.08 * open_frac
        top = _ellipse(cx, cy, rx, ry_up, 24, math.pi, 2 * math.pi)
        bottom = _ellipse(cx, cy, rx, ry_lo, 24, 0, math.pi)
        _fill(canvas, to_px, np.vstack([top, bottom]), (245, 245, 245))
        if open_frac > 0.25:
            iris_r = min(0.065, 0.9 * max(ry_up, ry_lo))
            _fill(canvas, to_px, _ellipse(cx, cy, iris_r, iris_r), (90, 70, 40))
            _fill(canvas, to_px, _ellipse(cx, cy, iris_r * 0.45, iris_r * 0.45), (15, 15, 15))
        _line(canvas, to_px, top, _LINE_BGR, 2.2 + 1.5 * squint, ss)
        _line(canvas, to_px, bottom, _LINE_BGR, 1.0 + 1.0 * squint, ss)
        if squint > 0.3:
            _crows_feet(canvas, to_px, side, cx + side * rx, cy, squint, ss)


def _crows_feet(canvas: np.ndarray, to_px: ToPx, side: int, x: float, y: float, squint: float,
                ss: int) -> None:
    """Three short lines fanning out from the outer eye corner, longer with the squint."""
    for k in (-1, 0, 1):
        length = 0.05 + 0.07 * squint
        pts = np.array([[x + side * 0.02, y + 0.02 * k], [x + side * (0.02 + length), y + 0.05 * k]])
        _line(canvas, to_px, pts, _LINE_BGR, 1.0, ss)


def _draw_brows(canvas: np.ndarray, to_px: ToPx, wt: dict[str, float], hair: BGR, ss: int) -> None:
    """Thick brows: down by up to 0.12 and in by 0.05, inner end lowest; frown lines above 0.3."""
    lower = wt["brow_lower"]
    for side in (-1, 1):
        inner = np.array([side * (0.1 - 0.05 * lower), -0.36 + 0.17 * lower])
        outer = np.array([side * 0.48, -0.4 + 0.07 * lower])
        mid = (inner + outer) / 2 + np.array([0, -0.06 * (1 - lower)])
        spine = _quad_bezier(inner, mid, outer, 16)
        thick = np.linspace(0.055, 0.03, 16)[:, None] * np.array([[0.0, 1.0]])
        _fill(canvas, to_px, np.vstack([spine - thick, (spine + thick)[::-1]]), hair)
    if lower > 0.3:
        for x in (-0.035, 0.035):
            pts = np.array([[x, -0.34 + 0.06 * lower], [x * 0.8, -0.26 + 0.06 * lower]])
            _line(canvas, to_px, pts, _LINE_BGR, 0.6 + 1.2 * lower, ss)


def _quad_bezier(p0: np.ndarray, p1: np.ndarray, p2: np.ndarray, n: int) -> np.ndarray:
    """``n`` points on the quadratic Bezier curve p0 -> p2 pulled towards p1."""
    t = np.linspace(0, 1, n)[:, None]
    return (1 - t) ** 2 * p0 + 2 * (1 - t) * t * p1 + t ** 2 * p2


def _draw_nose(canvas: np.ndarray, to_px: ToPx, ss: int) -> None:
    """A simple nose outline below the eyes."""
    pts = np.array([[0.0, -0.05], [-0.07, 0.22], [0.0, 0.26], [0.07, 0.22]])
    _line(canvas, to_px, pts[1:], _LINE_BGR, 1.5, ss)


def _draw_mouth(canvas: np.ndarray, to_px: ToPx, wt: dict[str, float], ss: int) -> None:
    """Lips between two corners: stretch widens and flattens, open drops the lower lip (jaw)."""
    stretch, opening = wt["mouth_stretch"], wt["mouth_open"]
    half_w = 0.2 + 0.17 * stretch
    y0 = 0.5 + 0.04 * stretch
    gap = 0.3 * opening
    smile = 0.03 * (1 - stretch)  # a relaxed mouth is slightly curved, a stretched one flat
    x = np.linspace(-half_w, half_w, 25)
    bulge = 1 - (x / half_w) ** 2
    upper = np.column_stack([x, y0 - smile * (1 - bulge) - 0.015 * bulge])
    inner_lo = np.column_stack([x, y0 + gap * bulge])
    if gap > 0.01:
        _fill(canvas, to_px, np.vstack([upper, inner_lo[::-1]]), (40, 30, 110))
        teeth = np.column_stack([x * 0.8, y0 + np.minimum(0.045, gap * 0.4) * bulge])
        _fill(canvas, to_px, np.vstack([upper * [0.8, 1], teeth[::-1]]), (235, 240, 240))
    lip = 3.0 - 1.6 * stretch
    _line(canvas, to_px, upper, (70, 70, 160), lip, ss)
    _line(canvas, to_px, inner_lo + [0, 0.02 * (1 - stretch) * bulge.mean()], (70, 70, 160),
          lip + 0.5, ss)
    for side in (-1, 1):  # dimples at the corners show the pull of a stretch
        if stretch > 0.3:
            cx = side * (half_w + 0.02)
            _line(canvas, to_px, np.array([[cx, y0 - 0.05], [cx + side * 0.02, y0 + 0.05]]),
                  _LINE_BGR, 1.0, ss)


def _light(img: np.ndarray, lighting: float, rng: np.random.Generator | None,
           noise_sd: float) -> np.ndarray:
    """Brightness factor with a gentle left-right gradient, and optional sensor noise."""
    h, w = img.shape[:2]
    gradient = 1.0 + 0.12 * (lighting - 1.0 + 0.5) * np.linspace(-1, 1, w, dtype=np.float32)
    out = img.astype(np.float32) * (np.float32(lighting) * gradient)[None, :, None]
    if rng is not None and noise_sd > 0:
        out += rng.normal(0.0, noise_sd, size=(h, w, 1)).astype(np.float32)
    return np.clip(np.rint(out), 0, 255).astype(np.uint8)
