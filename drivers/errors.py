"""One error hierarchy for every device family.

``DeviceError`` and its children wrap vendor, pyserial and pyusb errors (``raise ... from exc``)
and always name the device and the step that failed.
"""


class DeviceError(RuntimeError):
    """A device failed, is absent, or refused a request."""


class DeviceNotFoundError(DeviceError):
    """The device, its library or the permission to open it is missing."""


class DeviceTimeoutError(DeviceError, TimeoutError):
    """The device did not complete an operation within its own deadline."""


class WaitTimeoutError(DeviceError, TimeoutError):
    """The caller gave up waiting (as opposed to the device's own deadline running out)."""


class IncompatibleStateError(DeviceError):
    """The request is not valid in the device's current state (closed, not started, ...)."""


class UnsupportedFeatureError(DeviceError):
    """The device cannot do what was asked (a trigger combination, a bit depth, ...)."""


class ProtocolError(DeviceError):
    """A reply did not follow the device's protocol (garbled, wrong length, wrong id)."""
