"""fpp-rig application: command line, rig configuration, acquisition, capture store."""

__version__ = "0.1.0"
