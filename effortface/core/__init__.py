"""The shared core below every stage: errors, crash-safe file writing, the participant record and
its limits, the blendshape set, background jobs and figures (Qt-free); shared Qt widgets in ``gui/``.

Layers (checked by import-linter): core <- capture_tool <- annotate <- train <- the front door
(``effortface.cli``, ``effortface.app``, ``effortface.commands``, ``effortface.runtime``).
"""
