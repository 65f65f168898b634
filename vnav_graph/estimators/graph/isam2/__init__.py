"""The incremental front end of ``graph-isam2``: the iSAM2 online pass (``online``), its
relinearised interval factors (``linear_factors``, ``relin``) and window (``window``)."""
