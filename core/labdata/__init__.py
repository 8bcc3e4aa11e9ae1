"""Lab data out: the console's records as MCAP channels that lab tools (Foxglove, Lichtblick) open.

* :mod:`core.labdata.channels` -- the channel table (topic, schema name, JSON schema) and the
  pure mapping from a console record (``state``, ``action``, ``objects``, ``plan``, ...) to
  channel messages, including Foxglove's well-known ``foxglove.SceneUpdate``,
  ``foxglove.PoseInFrame`` and ``foxglove.Log``.
* :mod:`core.labdata.mcap_file` -- a synchronous MCAP writer and reader on the ``mcap`` package
  (no threads: the console's Recorder runs it on its writer thread, a CLI in its main thread).
* ``python -m core.labdata convert OLD.jsonl.gz NEW.mcap`` -- converts an old recording.
"""
