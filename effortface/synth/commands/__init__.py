"""``effortface synth``, ``effortface motion``, ``effortface work``."""
