"""The package version (``vnav_graph.__version__``), in a module that imports nothing."""

__version__ = "0.1.0"
