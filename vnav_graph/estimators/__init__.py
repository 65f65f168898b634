"""Estimators and their registry (see ``vnav_graph.estimators.base``)."""
