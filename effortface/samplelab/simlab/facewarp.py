"""Real faces for the sample lab: public-domain photographs warped by the four true weights.

Each participant has one photograph (``samplelab/data/faces``, see PROVENANCE.md there) and its 478
Face Mesh landmarks, computed once with MediaPipe and shipped, so the generator never needs a face
model. The photograph's lips are closed once (:func:`close_lips`). A frame is made in four steps:

1. **Landmark displacements per blendshape** (:func:`shape_displacements`), in a face frame whose
   unit is the distance between the eye centres (IOD), from the shapes' definitions (SCIENCE.md):
   ``mouth_open`` drops the jaw (chin, lower lip and the skin below the mouth move down by up to
   :data:`JAW_DROP_IOD`, lips part), ``mouth_stretch`` pulls the mouth corners sideways and as far
   down (a grimace) and thins the upper lip, ``eye_squint`` raises the lower lids and the cheeks and lowers the upper lids a little,
   ``brow_lower`` moves the brows down and together, pulling the skin above the eyes with them.
2. **Dense fields**: for each shape the landmarks (plus a fixed frame border) are triangulated and
   the displacement is interpolated linearly inside each triangle (a piecewise-affine warp,
   :func:`forward_field`), once per face.
3. **Per frame**: the weighted sum of the four fields (weights as :func:`shown`) is inverted by a few fixed-point iterations
   (:func:`inverse_map`: where each output pixel comes from), carried through
   the head's shift and roll and the downscale to the video size by one ``cv2.warpAffine`` of the map,
   then one ``cv2.remap`` of the photograph.
4. **The open mouth**: the gap between the displaced inner lip contours is painted as a dark mouth
   interior with the upper teeth's edge, then lighting and sensor noise are applied.

What the rater (a face model) cannot know: the weights, the expressiveness, the fields, the display
curve and the photograph's own neutral expression; it sees pixels only (SCIENCE_NOTES.md section 16).
"""

from __future__ import annotations

import dataclasses
import functools
from pathlib import Path

import numpy as np

FACES_DIR = Path(__file__).resolve().parent.parent / "data" / "faces"
#: one photograph per participant (PEOPLE order: P01 ... P06), see data/faces/PROVENANCE.md; the
#: open-smile portraits (the astronaut's jaw reads least) go to the most expressive participants
FACE_NAMES = ("bio_022126", "bio_022117", "bio_021506", "astronaut", "bio_021937", "bio_021342")

#: Face Mesh landmark indices (MediaPipe's canonical face model)
UPPER_INNER = (78, 191, 80, 81, 82, 13, 312, 311, 310, 415, 308)
LOWER_INNER = (78, 95, 88, 178, 87, 14, 317, 402, 318, 324, 308)
UPPER_OUTER = (61, 185, 40, 39, 37, 0, 267, 269, 270, 409, 291)
LOWER_OUTER = (61, 146, 91, 181, 84, 17, 314, 405, 321, 375, 291)
CORNERS = (61, 291, 78, 308, 62, 292, 76, 306)
EYES = {  # image-left eye, image-right eye: (upper lid, lower lid, iris)
    "a": ((246, 161, 160, 159, 158, 157, 173), (7, 163, 144, 145, 153, 154, 155), tuple(range(468, 473))),
    "b": ((466, 388, 387, 386, 385, 384, 398), (249, 390, 373, 374, 380, 381, 382), tuple(range(473, 478))),
}
EYE_CORNERS = {"a": (33, 133), "b": (263, 362)}
BROWS = {"a": (70, 63, 105, 66, 107, 46, 53, 52, 65, 55), "b": (300, 293, 334, 296, 336, 276, 283, 282, 295, 285)}
CHIN = 152

#: amplitudes at weight 1, in IOD (choice: a jaw drop to a widely open mouth, about 0.8 IOD, plus the
#: skin; a broad grimace, the corners pulled as far down as sideways, as in the paper's poses)
JAW_DROP_IOD = 0.5
STRETCH_IOD = 0.3
CORNER_JAW = 0.3  # share of the jaw drop the mouth corners follow
STRETCH_DOWN = 1.0  # downward pull of the stretched corners, share of the sideways pull
SQUINT_LID_FRACTION = 0.55  # of the eye's opening
CHEEK_RISE_IOD = 0.08
BROW_DROP_IOD = 0.17
MOUTH_BGR = (40, 32, 90)
#: fixed-point iterations inverting the forward warp per frame
INVERSE_ITERATIONS = 5
#: the warp's amplitude follows ``weight ** SHOW_GAMMA`` (choice: a face shows small efforts
#: visibly, as the paper's faces do; a face model barely sees a lid or lip that moves a pixel)
SHOW_GAMMA = 0.6
#: an open mouth hides a stretch from a viewer and a stretch an open mouth (measured with MediaPipe:
#: each reads the other as less), so each is drawn larger when the other is present (choice)
MOUTH_CROSS_GAIN = 0.6
TEETH_BGR = (190, 200, 210)


@dataclasses.dataclass(frozen=True)
class Face:
    """One photograph ready to warp: BGR crop, landmarks and four displacement fields (h, w, 2) in pixels."""

    image: np.ndarray
    landmarks: np.ndarray
    displacements: np.ndarray  # (4, 478, 2) forward, pixels at weight 1
    fields: np.ndarray  # (4, h, w, 2) forward displacement of every photo pixel, pixels at weight 1


def _frame(pts: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Origin (mid-eyes), rotation (rows: face x, face y) and IOD of a face."""
    ea = pts[list(EYES["a"][2])].mean(0)
    eb = pts[list(EYES["b"][2])].mean(0)
    ex = (eb - ea) / np.linalg.norm(eb - ea)
    rot = np.array([ex, [-ex[1], ex[0]]])
    return (ea + eb) / 2, rot, float(np.linalg.norm(eb - ea))


def shape_displacements(pts: np.ndarray) -> np.ndarray:
    """Forward landmark displacements (pixels) of the four shapes at weight 1, shape (4, n, 2).

    Order: mouth_stretch, mouth_open, eye_squint, brow_lower (the default set's order).
    """
    origin, rot, iod = _frame(pts)
    uv = (pts - origin) @ rot.T / iod  # face coordinates in IOD, v downwards
    u, v = uv[:, 0], uv[:, 1]
    n = len(pts)
    out = np.zeros((4, n, 2))
    inner = list(UPPER_INNER) + list(LOWER_INNER)
    mu, mv = uv[inner].mean(0)
    half_w = abs(uv[291, 0] - uv[61, 0]) / 2
    up_u, up_v = uv[list(UPPER_INNER), 0], uv[list(UPPER_INNER), 1]
    lo_v = uv[list(LOWER_INNER), 1]
    order = np.argsort(up_u)
    seam = np.interp(u, up_u[order], ((up_v + lo_v) / 2)[order])
    corner_v = (uv[61, 1] + uv[291, 1]) / 2
    du = (u - mu) / max(half_w, 1e-6)

    # mouth_stretch: corners sideways and a little down, lips thinner, falling off away from the mouth
    near = np.exp(-((u - mu) / (1.1 * half_w + 0.2)) ** 2 - ((v - mv) / 0.45) ** 2)
    st = out[0]
    st[:, 0] = STRETCH_IOD * np.clip(du, -1.2, 1.2) * near
    st[:, 1] = STRETCH_DOWN * STRETCH_IOD * np.clip(np.abs(du), 0, 1.2) ** 2 * near
    lips = np.array(sorted(set(UPPER_OUTER) - set(CORNERS)))  # the upper lip thins (the lower goes with the jaw)
    st[lips, 1] += -0.3 * (v[lips] - seam[lips]) * np.clip(1 - np.abs(du[lips]), 0, 1)

    # mouth_open: the jaw drops; the lower lip and everything below the mouth goes with it
    jo = out[1]
    inside = np.abs(u - mu) < half_w * 0.98
    below = np.where(inside, (v > seam).astype(float),
                     1.0 / (1.0 + np.exp(-(v - corner_v - 0.1) / 0.06)))
    lateral = np.clip(1.0 - 0.45 * ((u - mu) / 0.95) ** 2, 0.25, 1.0)
    jo[:, 1] = JAW_DROP_IOD * below * lateral
    oval = np.sqrt(np.clip(1.0 - du ** 2, 0.0, 1.0))  # the lips part as an oval, widest in the middle
    for ring in (LOWER_INNER[1:-1], LOWER_OUTER[1:-1]):
        jo[list(ring), 1] = JAW_DROP_IOD * (0.35 + 0.65 * oval[list(ring)])
    for c in (61, 78, 62, 76, 291, 308, 292, 306):  # corners: a third of the way, drawn in
        jo[c, 1] = CORNER_JAW * JAW_DROP_IOD
        jo[c, 0] = -0.04 * JAW_DROP_IOD * np.sign(du[c])
    jo[list(UPPER_OUTER[1:-1]) + list(UPPER_INNER[1:-1]), 1] = -0.06 * JAW_DROP_IOD * oval[list(UPPER_OUTER[1:-1]) + list(UPPER_INNER[1:-1])]

    # eye_squint: lower lids and cheeks rise, upper lids lower a little
    sq = out[2]
    for key, (upper, lower, iris) in EYES.items():
        opening = float(np.mean(v[list(lower)]) - np.mean(v[list(upper)]))
        eu, ev = uv[list(iris)].mean(0)
        sq[list(lower), 1] = -SQUINT_LID_FRACTION * opening * 0.75
        sq[list(upper), 1] = SQUINT_LID_FRACTION * opening * 0.25
        sq[list(iris), 1] = -SQUINT_LID_FRACTION * opening * 0.25
        cheek = np.exp(-((u - eu) / 0.35) ** 2 - ((v - ev - 0.45) / 0.3) ** 2)
        cheek[list(upper) + list(lower) + list(iris) + list(EYE_CORNERS[key])] = 0
        sq[:, 1] -= CHEEK_RISE_IOD * cheek
        sq[list(EYE_CORNERS[key]), 1] = -0.1 * opening

    # brow_lower: brows down and together; the skin above the eyes follows
    bl = out[3]
    brow_v = float(np.mean(v[list(BROWS["a"] + BROWS["b"])]))
    eye_v = float(np.mean(v[list(EYES["a"][0] + EYES["b"][0])]))
    t = np.clip((eye_v - v) / max(eye_v - brow_v, 1e-6), 0.0, None)  # 0 at the lids, 1 at the brows
    fall = np.where(t <= 1.0, 0.1 + 0.9 * t, np.exp(-((t - 1.0) / 0.9) ** 2))
    fall *= np.abs(u) < 1.25
    bl[:, 1] = BROW_DROP_IOD * fall * (v < eye_v)
    bl[:, 0] = -0.35 * BROW_DROP_IOD * np.clip(u / 0.6, -1, 1) * fall * (v < eye_v) * np.exp(-(u / 0.7) ** 2)
    for key in EYES:
        bl[list(EYES[key][0]), 1] = 0.08 * BROW_DROP_IOD
        bl[list(EYES[key][1]) + list(EYES[key][2]) + list(EYE_CORNERS[key]), :] = 0.0
    return out @ rot * iod  # back to image axes, pixels


def forward_field(pts: np.ndarray, disp: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """Piecewise-affine displacement field (h, w, 2) on the photograph: where each source pixel goes.

    The landmarks and a fixed border are triangulated (Delaunay) and ``disp`` is interpolated
    linearly inside each triangle, so a weighted sum of fields is the piecewise-affine warp of the
    weighted landmark displacements, exactly.
    """
    from scipy.interpolate import LinearNDInterpolator

    w, h = size
    border = np.array([[x, y] for x in np.linspace(-2, w + 1, 9) for y in (-2, h + 1)]
                      + [[x, y] for y in np.linspace(-2, h + 1, 7) for x in (-2, w + 1)])
    src = np.concatenate([pts, border])
    val = np.concatenate([disp, np.zeros_like(border)])
    interp = LinearNDInterpolator(src, val, fill_value=0.0)
    gy, gx = np.mgrid[0:h, 0:w]
    return interp(gx.ravel(), gy.ravel()).reshape(h, w, 2).astype(np.float32)


def inverse_map(field: np.ndarray, iterations: int = INVERSE_ITERATIONS) -> np.ndarray:
    """The source position of every output pixel, (h, w, 2), for the forward ``field``: the fixed
    point of ``y = x - field(y)`` by a few iterations (each one ``cv2.remap`` of the field)."""
    from effortface.core.opencv import import_cv2

    cv2 = import_cv2()
    h, w = field.shape[:2]
    gy, gx = np.mgrid[0:h, 0:w].astype(np.float32)
    grid = np.dstack([gx, gy])
    y = grid - field
    for _ in range(iterations - 1):
        y = grid - cv2.remap(field, y[..., 0], y[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return y


@functools.lru_cache(maxsize=8)
def load_face(index: int) -> Face:
    """Participant ``index``'s photograph, landmarks and fields (cached)."""
    from effortface.core.opencv import import_cv2

    cv2 = import_cv2()
    name = FACE_NAMES[index % len(FACE_NAMES)]
    image = cv2.imread(str(FACES_DIR / f"{name}.jpg"), cv2.IMREAD_COLOR)
    if image is None:
        raise FileNotFoundError(f"{FACES_DIR / (name + '.jpg')}: expected a face photograph, found none")
    pts = np.load(FACES_DIR / f"{name}_landmarks.npy").astype(np.float64)
    size = (image.shape[1], image.shape[0])
    image, pts = close_lips(image, pts)
    disp = shape_displacements(pts)
    fields = np.stack([forward_field(pts, d, size) for d in disp])
    return Face(image, pts, disp, fields)


def close_lips(image: np.ndarray, pts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The photograph with its lips closed (a smile that shows teeth becomes a closed-lip smile):
    the neutral face of the lab, from which the jaw drop opens the mouth.

    The lower inner lip is moved onto the upper one and the jaw raised by the median gap (the
    mouth_open field, reversed), baked into the image once; returns the image and its landmarks.
    """
    from effortface.core.opencv import import_cv2

    cv2 = import_cv2()
    origin, rot, iod = _frame(pts)
    gaps = (pts[list(LOWER_INNER)] - pts[list(UPPER_INNER)]) @ rot[1]  # along the face's vertical
    gap = float(np.median(np.clip(gaps[1:-1], 0.0, None)))
    if gap < 0.5:
        return image, pts
    jaw = shape_displacements(pts)[1]
    base = -jaw * gap / (JAW_DROP_IOD * iod)
    base[list(LOWER_INNER)] = -np.clip(gaps, 0.0, None)[:, None] * rot[1][None, :]
    size = (image.shape[1], image.shape[0])
    source = inverse_map(forward_field(pts, base, size))
    closed = cv2.remap(image, source[..., 0], source[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return closed, pts + base


def _affine(face: Face, size: tuple[int, int], pose: np.ndarray) -> np.ndarray:
    """2x3 matrix from crop pixels to output pixels: downscale, roll about the face, shift."""
    from effortface.core.opencv import import_cv2

    cv2 = import_cv2()
    h0, w0 = face.image.shape[:2]
    s = size[0] / w0
    centre = face.landmarks.mean(0)
    m = cv2.getRotationMatrix2D((float(centre[0]), float(centre[1])), float(pose[2]), s)
    m[:, 2] += (s - 1.0) * centre  # the face centre lands where plain scaling puts it
    m[0, 2] += (size[0] - s * w0) / 2 + pose[0] * size[0]
    m[1, 2] += (size[1] - s * h0) / 2 + pose[1] * size[1]
    return m


def render(face: Face, weights: np.ndarray, size: tuple[int, int], pose: np.ndarray, light: float,
           rng: np.random.Generator, noise_sd: float = 1.5) -> np.ndarray:
    """One BGR video frame of ``face`` showing ``weights`` (default-set order), head ``pose``
    ``(dx, dy, roll_deg)``, brightness ``light`` and sensor noise."""
    from effortface.core.opencv import import_cv2

    cv2 = import_cv2()
    w = shown(weights)
    crop_map = inverse_map(np.tensordot(w, face.fields, axes=1).astype(np.float32))
    m = _affine(face, size, pose)
    # the map is sampled at each output pixel's crop position (m's inverse)
    out_map = cv2.warpAffine(crop_map, cv2.invertAffineTransform(m), size,
                             flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP, borderMode=cv2.BORDER_REPLICATE)
    img = cv2.remap(face.image, out_map, None, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    _paint_mouth(img, face, w, m)
    img = img.astype(np.float32) * float(light) + rng.normal(0.0, noise_sd, img.shape).astype(np.float32)
    return np.clip(img, 0, 255).astype(np.uint8)


def shown(weights: np.ndarray) -> np.ndarray:
    """The warp amplitudes of four weights: ``weight ** SHOW_GAMMA``, and a stretch and a jaw drop
    made the more pronounced the more the other is present (``MOUTH_CROSS_GAIN``)."""
    w = np.clip(np.asarray(weights, dtype=np.float64), 0.0, 1.0) ** SHOW_GAMMA
    stretch, jaw = w[0], w[1]
    w[0] = stretch * (1.0 + MOUTH_CROSS_GAIN * jaw)
    w[1] = jaw * (1.0 + MOUTH_CROSS_GAIN * stretch)
    return w.astype(np.float32)


def _paint_mouth(img: np.ndarray, face: Face, w: np.ndarray, m: np.ndarray) -> None:
    """Paint the gap the jaw drop opened: a dark mouth interior below the upper teeth's edge.

    The gap runs from where the lower inner lip would be without the jaw drop (the photograph's own
    lips, teeth and all, stay as they are) down to where it is; the teeth's edge tapers towards the
    mouth corners.
    """
    from effortface.core.opencv import import_cv2

    cv2 = import_cv2()
    shut = w.astype(np.float64).copy()
    shut[1] = 0.0
    lo = list(LOWER_INNER)
    top = (face.landmarks[lo] + np.tensordot(shut, face.displacements[:, lo], axes=1)) @ m[:, :2].T + m[:, 2]
    bottom = (face.landmarks[lo] + np.tensordot(w.astype(np.float64), face.displacements[:, lo], axes=1)) \
        @ m[:, :2].T + m[:, 2]
    gap = float(np.max(bottom[:, 1] - top[:, 1]))
    if gap < 0.5:
        return
    shift = 4
    taper = np.sin(np.linspace(0.0, np.pi, len(lo)))[:, None]
    edge = top + taper * np.array([0.0, min(0.18 * gap, 2.0)])

    def fill(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        mask = np.zeros(img.shape[:2], np.uint8)
        cv2.fillPoly(mask, [np.round(np.concatenate([a, b[::-1]]) * (1 << shift)).astype(np.int32)], 255,
                     cv2.LINE_AA, shift)
        return (mask.astype(np.float32) / 255.0)[..., None]

    alpha, tooth = fill(top, bottom), fill(top, edge)
    tooth = np.minimum(alpha, tooth)
    colour = np.array(MOUTH_BGR, np.float32) * (1 - tooth) + np.array(TEETH_BGR, np.float32) * tooth
    img[:] = np.clip(img * (1 - alpha) + colour * alpha, 0, 255).astype(np.uint8)
