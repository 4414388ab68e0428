"""Where a real robot's photos come from, matched to the moment the shutter was triggered.

Foster et al. (section III) fire the camera from an NXT motor port and receive the photo on
the host through a wireless SD card: the photo appears as a new file in a folder some time
after the trigger. `FolderPhotoSource` watches such a folder and takes the first new file
written after the trigger; `OpenCVPhotoSource` grabs a frame from an OpenCV capture device
(a webcam index, a video file or an image-sequence pattern) at the trigger instead.
Images are (H, W, 3) uint8 RGB.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Protocol

import numpy as np

from ibr.errors import InputError
from ibr.scene import SceneError, read_image

IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png", ".JPG", ".JPEG", ".PNG")


class PhotoTimeoutError(InputError):
    """No photo arrived for a shutter trigger."""


class PhotoSource(Protocol):
    def arm(self) -> None:
        """Called just before the shutter is triggered."""

    def fetch(self, trigger_time: float, timeout_s: float) -> tuple[np.ndarray, str]:
        """The photo of the trigger at wall-clock `trigger_time` (s since the epoch):
        (image (H, W, 3) uint8, where it came from)."""


class FolderPhotoSource:
    """Photos that arrive as files in `folder`. A photo matches a trigger when its file is
    new since `arm()` and was modified no earlier than `slack_s` before the trigger; of
    several, the earliest. Files still being written (truncated) are retried."""

    def __init__(self, folder: str | Path, slack_s: float = 1.0, poll_s: float = 0.02):
        self.folder = Path(folder)
        if not self.folder.is_dir():
            raise InputError(f"{self.folder}: photo folder does not exist")
        self.slack_s, self.poll_s = slack_s, poll_s
        self._seen = set(self._files())

    def _files(self) -> list[Path]:
        return [p for p in self.folder.iterdir() if p.suffix in IMAGE_SUFFIXES and not p.name.startswith(".")]

    def arm(self) -> None:
        self._seen.update(self._files())

    def fetch(self, trigger_time: float, timeout_s: float) -> tuple[np.ndarray, str]:
        deadline = time.monotonic() + timeout_s
        while True:
            fresh = []
            for p in self._files():
                if p in self._seen:
                    continue
                try:
                    mtime = p.stat().st_mtime
                except FileNotFoundError:
                    continue
                if mtime >= trigger_time - self.slack_s:
                    fresh.append((mtime, p))
                else:
                    self._seen.add(p)  # stale: older than this trigger
            for _, p in sorted(fresh):
                try:
                    image = read_image(p)
                except SceneError:
                    continue  # still being written; try again next poll
                self._seen.add(p)
                return image, str(p)
            if time.monotonic() > deadline:
                raise PhotoTimeoutError(f"{self.folder}: no new photo appeared within {timeout_s:.1f} s "
                                        "of the shutter trigger (is the camera on and its card sending?)")
            time.sleep(self.poll_s)


class OpenCVPhotoSource:
    """Frames from an OpenCV `VideoCapture` (device index, video file, or image-sequence
    pattern such as 'frames/img_%03d.png'), one grabbed per trigger."""

    def __init__(self, device: int | str):
        import cv2

        self.device = device
        self.capture = cv2.VideoCapture(device)
        if not self.capture.isOpened():
            raise InputError(f"{device}: cannot open the OpenCV capture device")

    def arm(self) -> None:
        pass

    def fetch(self, trigger_time: float, timeout_s: float) -> tuple[np.ndarray, str]:
        deadline = time.monotonic() + timeout_s
        while True:
            ok, frame = self.capture.read()
            if ok:
                return np.ascontiguousarray(frame[..., ::-1]), f"{self.device}"
            if time.monotonic() > deadline:
                raise PhotoTimeoutError(f"{self.device}: the capture device gave no frame within {timeout_s:.1f} s")
            time.sleep(0.01)

    def close(self) -> None:
        self.capture.release()
