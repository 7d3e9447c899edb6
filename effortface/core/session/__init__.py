"""The session-folder format (``session.json``, ``heart_rate.csv``, frames, events): read,
write and check, Qt-free, below every stage."""
