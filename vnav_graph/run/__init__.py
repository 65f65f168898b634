"""The run layer: what ``vnav-graph run`` and ``bench`` do with a drive.

- ``runner``: runs estimators on a drive (order, warm-ups, captured warnings, holdout);
- ``pipeline``: one run end to end (load, run, score, self-check, write outputs);
- ``bench``: the Monte Carlo over scenarios × seeds × estimators;
- ``runtime_estimate``: how long a run will take, before it starts;
- ``outputs``: the output directory and its files;
- ``progress``: progress bars and their modes.
"""
