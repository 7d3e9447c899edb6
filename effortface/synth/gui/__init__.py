"""The Synthesize stage's Qt widgets."""
