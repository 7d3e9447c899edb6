"""The body model and everything game code needs: motion readers, segments, energies, work,
filters, physiology, the runtime, curve files, synthesis and batch synthesis (the Synthesize
stage). Below training: ``effortface.train`` imports it, never the reverse."""
