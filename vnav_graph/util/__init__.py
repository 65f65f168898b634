"""Infrastructure the package runs on, with no navigation in it.

- ``jit``: numba's on-disk cache, compile-time accounting and warm-ups;
- ``pages``: the memory pages of numpy's large temporaries (``small_pages``);
- ``failures``: the one-line message of any exception (``failure_message``) and the
  exception types ``MissingStream`` and ``ExtensionError``;
- ``suggest``: "did you mean" for names typed by a user.
"""
