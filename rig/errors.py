"""Errors a user can cause: the CLI prints them as one line and exits non-zero.

Device errors live in :mod:`drivers.errors` (drivers must not import ``rig``);
the CLI treats both families alike.
"""


class RigError(Exception):
    """Base of every error caused by input, configuration or data, not by a bug."""


class CaptureError(RigError):
    """A capture directory is missing, malformed, incomplete or corrupt."""


class CalibrationError(RigError):
    """A calibration is missing, malformed, or does not fit the capture or the data."""


class ConfigError(RigError):
    """A rig configuration file or a command-line value is wrong."""


class ProcessingError(RigError):
    """The data cannot be processed (for example every pixel is in shadow)."""
