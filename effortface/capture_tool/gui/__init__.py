"""Qt widgets of the Capture stage (the only place in capture_tool that imports Qt)."""
