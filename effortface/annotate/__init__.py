"""Stage 2, annotate: key-frame tracks, video index, agreement statistics, the parametric face."""
