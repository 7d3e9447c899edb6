"""The machine rater: MediaPipe's Face Landmarker on every recorded frame (``effortface preannotate``).

- :mod:`~effortface.annotate.machine.landmarker`: the pipeline (detector, landmarks, blendshapes) on
  the bundle's ``.tflite`` models with ``ai-edge-litert`` (:mod:`effortface.core.face_landmarker`,
  which Capture's framing check runs too).
- :mod:`~effortface.annotate.machine.track`: the files (``machine/face_landmarker.csv`` and its sidecar).
- :mod:`~effortface.annotate.machine.mapping`: 52 scores -> our four blendshapes, and the calibration.
- :mod:`~effortface.annotate.machine.preannotate`: one session rated.

Imports nothing heavy at package level (the TFLite interpreter and OpenCV load when used).
"""
