"""Errors a user can cause: the CLI prints them as one line and exits non-zero.

Device errors live in :mod:`drivers.errors` and calibration errors in :mod:`calibration.errors`
(those packages must not import ``rig``); the CLI treats all of ``USER_ERRORS`` alike.
"""

from calibration.errors import CalibrationError
from drivers.errors import DeviceError


class RigError(Exception):
    """Base of every error caused by input, configuration or data, not by a bug."""


class CaptureError(RigError):
    """A capture directory is missing, malformed, incomplete or corrupt."""


class ConfigError(RigError):
    """A rig configuration file or a command-line value is wrong."""


class OutputError(RigError):
    """An output cannot be written where asked: unwritable, or it would replace something not ours."""


class ResultExistsError(OutputError):
    """A result directory exists and replacing it was not asked for (the console answers 409)."""


class ProcessingError(RigError):
    """The data cannot be processed (for example every pixel is in shadow)."""


# What the CLI reports as one line and a non-zero exit, never as a traceback.
USER_ERRORS: tuple[type[Exception], ...] = (RigError, DeviceError, CalibrationError)


def os_error_line(exc: OSError) -> str:
    """What the operating system refused, as the one line a user reads: the file, then the reason."""
    where = f"{exc.filename}: " if exc.filename else ""
    return f"{where}{exc.strerror or exc}"
