"""The calibration package's user-facing error (``calibration`` must not import ``rig``)."""


class CalibrationError(ValueError):
    """A calibration is missing, malformed, singular, or does not fit the capture or the data."""
