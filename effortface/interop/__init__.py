"""Interoperability with lab and engine tools: LSL, XDF, BIDS, C3D, the engine reference, the live server."""
