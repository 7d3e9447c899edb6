"""Qt widgets of the Annotate stage."""
