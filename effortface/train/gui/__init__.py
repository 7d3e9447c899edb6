"""Qt widgets of the Train and Synthesize stages."""
