"""``pyrealsense2``, imported on first use: it is an optional extra, and on Linux its wheel needs
the system library libusb-1.0 even to read a recording. Without either, a clear error says what
to install."""

from __future__ import annotations

from types import ModuleType

#: what a user runs to get RealSense support
INSTALL_HINT = ("pip install 'gngdt[realsense]' (pyrealsense2: wheels for Linux x86_64 and "
                "Windows); on Linux it also needs the system library libusb-1.0 "
                "(Debian/Ubuntu: apt-get install libusb-1.0-0)")


class RealSenseUnavailable(ImportError):
    """pyrealsense2 cannot be imported; the message says what to install."""


def pyrealsense() -> ModuleType:
    """The ``pyrealsense2`` module, or `RealSenseUnavailable` saying what is missing."""
    try:
        import pyrealsense2
    except ImportError as error:
        raise RealSenseUnavailable(unavailable_reason(error)) from error
    return pyrealsense2


def unavailable_reason(error: ImportError) -> str:
    """Why pyrealsense2 did not import, and what to install."""
    text = str(error)
    if "libusb" in text:
        return (f"pyrealsense2 is installed but cannot load the system library libusb-1.0 "
                f"({text}); install it: apt-get install libusb-1.0-0 (Debian/Ubuntu)")
    if isinstance(error, ModuleNotFoundError) and error.name == "pyrealsense2":
        return f"RealSense support is an optional extra that is not installed: {INSTALL_HINT}"
    return f"pyrealsense2 cannot be imported ({text}): {INSTALL_HINT}"


def availability() -> str | None:
    """None when pyrealsense2 imports, else the reason it does not (for skips and --help)."""
    try:
        pyrealsense()
    except RealSenseUnavailable as error:
        return str(error)
    return None
