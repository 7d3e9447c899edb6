"""The machine rater's engine: MediaPipe's Face Landmarker on the bundle's three ``.tflite`` models.

It lives in :mod:`effortface.core.face_landmarker` (Capture's framing check runs it too); this
module keeps the names the machine rater and its users import from here.
"""

from __future__ import annotations

from effortface.core.face_landmarker import (ARKIT_NAMES, BLENDSHAPE_LANDMARKS, BLENDSHAPES_TFLITE, CROP_SCALE,
                                             DEFAULT_MODEL, DEFAULT_MODEL_SHA256, DETECTOR_TFLITE, EYE_CORNERS,
                                             LANDMARKS_TFLITE, LITERT_LOG_ENV, MAX_TASK_BYTES,
                                             MIN_DETECTION_CONFIDENCE, MIN_PRESENCE_CONFIDENCE, NMS_IOU,
                                             FaceLandmarker, FaceResult, OneEuroSmoother, Rect, as_rgb,
                                             litert_interpreter, read_bundle, rect_from_points, ssd_anchors,
                                             weighted_nms)
from effortface.core.fileio import file_sha256

__all__ = ["ARKIT_NAMES", "BLENDSHAPE_LANDMARKS", "BLENDSHAPES_TFLITE", "CROP_SCALE", "DEFAULT_MODEL",
           "DEFAULT_MODEL_SHA256", "DETECTOR_TFLITE", "EYE_CORNERS", "LANDMARKS_TFLITE", "LITERT_LOG_ENV",
           "MAX_TASK_BYTES", "MIN_DETECTION_CONFIDENCE", "MIN_PRESENCE_CONFIDENCE", "NMS_IOU", "FaceLandmarker",
           "FaceResult", "OneEuroSmoother", "Rect", "as_rgb", "file_sha256", "litert_interpreter", "read_bundle",
           "rect_from_points", "ssd_anchors", "weighted_nms"]
