"""The incremental front end of ``graph-isam2``; its modules are listed in
``vnav_graph.estimators.graph`` and docs/design.md."""
