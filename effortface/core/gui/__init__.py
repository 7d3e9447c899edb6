"""Qt pieces shared by every stage (widgets, the PySide6 refcount guard, GUI-thread garbage collection)."""
