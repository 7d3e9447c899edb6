"""The machine rater: MediaPipe's Face Landmarker on every recorded frame (``effortface preannotate``).

- :mod:`~effortface.annotate.machine.landmarker`: the pipeline (detector, landmarks, blendshapes) on
  the bundle's ``.tflite`` models with ``ai-edge-litert`` (:mod:`effortface.core.face_landmarker`,
  which Capture's framing check runs too).
- :mod:`~effortface.annotate.machine.track`: the files (``machine/face_landmarker.csv`` and its sidecar).
- :mod:`~effortface.annotate.machine.mapping`: the definition mapping (52 scores -> our four
  blendshapes, the mean of the ARKit scores each names), and the isotonic calibration.
- :mod:`~effortface.annotate.machine.effort`: the effort mapping the rater uses (eye_squint held across
  blinks, mouth_stretch less a smile, baselines removed by a neutral reference).
- :mod:`~effortface.annotate.machine.learned`: the learned mapping where the lab has human keys, scored
  leave-one-participant-out against the effort mapping.
- :mod:`~effortface.annotate.machine.preannotate`: one session rated.

Imports nothing heavy at package level (the TFLite interpreter and OpenCV load when used).
"""
