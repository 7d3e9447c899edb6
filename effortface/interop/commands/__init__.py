"""``effortface serve``, ``effortface import``, ``effortface export``."""
