"""Where camera images come from: an OpenCV capture device or stream, a video file, a folder of images
replayed at a rate, or images in memory. Every frame carries its capture time (`time.monotonic()`).

A replay behaves like a live camera with a one-frame buffer: frame k is due at start + k / rate; a reader
that falls behind gets the newest due frame (the ones in between are dropped and counted), and the frame's
capture time is when it was due, so a slow pipeline shows up as latency. No PyBullet, no torch.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import cv2
import numpy as np

from mrguide.errors import InputError

log = logging.getLogger(__name__)

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")


class CameraError(InputError):
    """A camera source that cannot be used: a device that does not open, a folder without images, ..."""


class FrameGrabError(RuntimeError):
    """One frame could not be had (a failed grab, an unreadable image); the next one may work."""


@dataclass(frozen=True)
class Frame:
    """An RGB uint8 image (H, W, 3) and when it was captured (`time.monotonic()`, s)."""

    image: np.ndarray
    t_capture: float


class FrameSource(Protocol):
    """A camera as the pose source sees it."""

    def read(self) -> Frame | None:
        """The next frame (blocks until there is one); None when the source has no more. FrameGrabError
        when this one failed."""
        ...

    def close(self) -> None:
        """Release the device (idempotent)."""
        ...


class CaptureFrames:
    """`cv2.VideoCapture` of a device index, a stream URL or a video file, asked for a one-frame buffer."""

    def __init__(self, source: int | str, size: tuple[int, int] | None = None):
        self.source = source
        self.cap = cv2.VideoCapture(source)
        if not self.cap.isOpened():
            self.cap.release()
            kind = "device" if isinstance(source, int) else "stream or file"
            raise CameraError(f"camera source {source!r}: OpenCV cannot open this {kind}")
        self.cap.set(cv2.CAP_PROP_BUFFERSIZE, 1)  # the newest frame, not a queue of old ones (where supported)
        if size is not None:
            self.cap.set(cv2.CAP_PROP_FRAME_WIDTH, size[0])
            self.cap.set(cv2.CAP_PROP_FRAME_HEIGHT, size[1])

    def read(self) -> Frame:
        if not self.cap.grab():
            raise FrameGrabError(f"camera source {self.source!r}: frame grab failed")
        t = time.monotonic()
        ok, bgr = self.cap.retrieve()
        if not ok or bgr is None:
            raise FrameGrabError(f"camera source {self.source!r}: cannot decode the grabbed frame")
        return Frame(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB), t)

    def close(self) -> None:
        self.cap.release()


class ReplayFrames:
    """`count` images from `load(k)` in order at `rate_hz` (0: as fast as they are read), once or looped."""

    def __init__(
        self,
        count: int,
        load: Callable[[int], np.ndarray],
        rate_hz: float,
        loop: bool = False,
        clock: Callable[[], float] = time.monotonic,
    ):
        self.count, self.load, self.rate, self.loop, self.clock = count, load, rate_hz, loop, clock
        self.dropped = 0
        self._next = 0
        self._t0: float | None = None

    def read(self) -> Frame | None:
        now = self.clock()
        if self._t0 is None:
            self._t0 = now
        if self.rate > 0:
            k = max(self._next, int((now - self._t0) * self.rate))
            t = self._t0 + k / self.rate
            if t > now:
                time.sleep(t - now)
        else:
            k, t = self._next, now
        if k >= self.count and not self.loop:
            return None
        self.dropped += k - self._next
        self._next = k + 1  # before loading: an unreadable image is skipped, not retried forever
        return Frame(self.load(k % self.count), t)

    def close(self) -> None:
        """Nothing to release."""


def memory_frames(images: Sequence[np.ndarray], rate_hz: float, loop: bool = True) -> ReplayFrames:
    """RGB images held in memory, replayed (the benchmark's camera)."""
    if not images:
        raise CameraError("memory replay: no images")
    return ReplayFrames(len(images), lambda k: images[k], rate_hz, loop)


def folder_frames(folder: Path, rate_hz: float, loop: bool = False) -> ReplayFrames:
    """The images of `folder` in name order, read as they are replayed."""
    if not folder.is_dir():
        raise CameraError(f"camera source {str(folder)!r}: no such folder")
    files = sorted(f for f in folder.iterdir() if f.suffix.lower() in IMAGE_SUFFIXES)
    if not files:
        raise CameraError(f"camera source {str(folder)!r}: the folder holds no images ({', '.join(IMAGE_SUFFIXES)})")

    def load(k: int) -> np.ndarray:
        bgr = cv2.imread(str(files[k]), cv2.IMREAD_COLOR)
        if bgr is None:
            raise FrameGrabError(f"{files[k]}: cannot read the image (corrupt or not an image)")
        return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)

    return ReplayFrames(len(files), load, rate_hz, loop)


def open_frames(
    source: int | str, base_dir: Path, rate_hz: float, loop: bool, size: tuple[int, int] | None = None
) -> FrameSource:
    """A device index, a URL (with "://"), or a folder of images / a video file (relative to `base_dir`)."""
    if isinstance(source, int):
        return CaptureFrames(source, size)
    if "://" in source:
        return CaptureFrames(source)
    path = base_dir / source
    if path.is_dir():
        return folder_frames(path, rate_hz, loop)
    if path.is_file():
        return CaptureFrames(str(path))
    raise CameraError(f"camera source {source!r}: no such folder or file ({path})")
