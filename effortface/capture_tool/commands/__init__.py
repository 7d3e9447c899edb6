"""Command-line sub-commands of stage 1 (one module each: add_arguments, run)."""
