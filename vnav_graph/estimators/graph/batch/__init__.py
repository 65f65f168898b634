"""``graph-batch``: the whole drive solved at once by the shared solver (``..solver``)."""
