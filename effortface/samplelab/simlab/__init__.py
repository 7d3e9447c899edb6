"""The simulated lab behind the sample lab: participants, exercise plans, an independent heart-rate
simulation, protocol byte streams, face curves, video and raters.

Used only by :mod:`effortface.samplelab.generate` and the tests; no stage imports it.
"""
