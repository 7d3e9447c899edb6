"""The shared core below every stage: errors, crash-safe file writing, the participant record and
its limits, the blendshape set, background jobs and figures (Qt-free); shared Qt widgets in ``gui/``.

Layers (checked by import-linter): core <- capture_tool <- annotate <- train <- the front door
(``effortface.cli``, ``effortface.app``, ``effortface.commands``, ``effortface.runtime``).

The stage convention (one for Capture, Annotate, Train and Synthesize; ``tests/test_conventions.py``
checks it):

1. **Model.** A stage's model is Qt-free and lives at the stage package root, named
   ``<stage>_session.py`` with the class ``<Stage>Session``: ``effortface/capture_tool/capture_session.py``
   ``CaptureSession``, ``effortface/annotate/annotate_session.py`` ``AnnotateSession``,
   ``effortface/train/train_session.py`` ``TrainSession``, ``effortface/synth/synth_session.py`` ``SynthSession``. Its view
   is ``Qt<Stage>Stage`` in the stage's ``gui/`` folder.
2. **Change notification.** The model owns one :class:`effortface.core.events.Emitter` per thing
   that changes, named ``<thing>_changed`` (``frame_changed``, ``status_changed(text, is_error)``...).
   A view takes the model in ``__init__`` (as ``self.session``), connects to its emitters there, and
   writes back only through model methods; it keeps widget state only (the rule: a view writes back only through model methods and keeps widget state only).
3. **Background work.** Blocking work (opening devices, stopping a recording, training, exporting,
   recomputing curves) goes through :class:`effortface.core.jobs.Jobs`, usually owned by the model:
   ``jobs.submit(key, fn, *args, done=self._handler)``, with ``progress=`` and ``takes_job=True`` for
   work that reports progress and checks :meth:`~effortface.core.jobs.Job.check` so that
   :meth:`~effortface.core.jobs.Jobs.cancel` can stop it. The stage's QTimer calls the model's
   ``poll()``, which calls :meth:`~effortface.core.jobs.Jobs.drain`: the callbacks run on the GUI
   thread, never waiting (the rule: worker threads hand their results to the GUI thread, which drains them on a timer; no thread touches a widget). A view with no model of its own (the device pre-flight) may
   own a ``Jobs`` and drain it on its own QTimer.
4. **Explicit connections.** Every job names its ``done`` callback; no handler is looked up by a
   name built at run time (``getattr(self, f"_on_{key}")``).
"""
