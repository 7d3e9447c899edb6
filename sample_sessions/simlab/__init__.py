"""The simulated lab behind ``sample_sessions/``: participants, exercise plans, an independent
heart-rate simulation, protocol byte streams, face curves, video and raters.

Used only by ``sample_sessions/generate.py`` and the tests; no stage imports it.
"""
