"""Files in and out: the ``quadfault-recording/1`` format (:mod:`quadfault.io.recording`),
state samples, and the importers of autopilot logs (:mod:`quadfault.io.importers`). This
layer sits above the model and below the diagnosis; it never imports the diagnosis."""
