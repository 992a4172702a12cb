"""emlogd: EMlog calibration daemon and offline tools."""

from drivers.errors import CaptureFormatError, ConfigError, DeviceError, EmlogdError

__version__ = "0.1.0"

__all__ = ["CaptureFormatError", "ConfigError", "DeviceError", "EmlogdError", "__version__"]
