"""Errors raised by the calibration package; each message names what is wrong and where."""

from __future__ import annotations

from mrguide.errors import InputError


class CalibrationError(InputError):
    """Bad input to calibration: an image, an intrinsics file, a dictionary name, a target layout."""


class NotEnoughMarkersError(CalibrationError):
    """Fewer markers (or frames) were usable than the configured minimum, so no transform is returned."""


class CalibrationFileError(CalibrationError):
    """A calibration file is missing, corrupt, or does not match what the caller expects."""
