"""Reading camera frames for tracking: a folder of PNG images (in name order) or a video file."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np

from ..errors import StressbotsError

__all__ = ["frame_source", "VIDEO_SUFFIXES"]

#: File suffixes read as video (through OpenCV's VideoCapture).
VIDEO_SUFFIXES = (".avi", ".mp4", ".mov", ".mkv", ".m4v", ".mpg", ".mpeg", ".wmv")


def _grey(img: np.ndarray) -> np.ndarray:
    import cv2

    if img.ndim == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY if img.shape[2] == 3 else cv2.COLOR_BGRA2GRAY)
    if img.dtype != np.uint8:  # 16-bit PNG: scale to 8 bits
        img = (img.astype(np.float64) * (255.0 / max(float(img.max()), 1.0))).astype(np.uint8)
    return img


def frame_source(path: Path | str) -> tuple[int, Iterator[tuple[str, np.ndarray]]]:
    """The number of frames (or -1 if a video does not say) and an iterator of ``(name, grey uint8 frame)``.

    Raises :class:`StressbotsError` for a missing path, a folder without PNG files, or a file OpenCV
    cannot read.
    """
    try:
        import cv2
    except ImportError:
        raise StressbotsError("reading frames needs OpenCV: pip install 'stressbots[lab]'", source=str(path)) from None
    p = Path(path)
    if p.is_dir():
        files = sorted(f for f in p.iterdir() if f.suffix.lower() == ".png")
        if not files:
            raise StressbotsError("no .png frames in this folder", source=str(p))

        def images() -> Iterator[tuple[str, np.ndarray]]:
            for f in files:
                img = cv2.imread(str(f), cv2.IMREAD_UNCHANGED)
                if img is None:
                    raise StressbotsError("not a readable PNG image", source=str(f))
                yield f.name, _grey(img)

        return len(files), images()
    if not p.exists():
        raise StressbotsError("no such file or folder", source=str(p))
    if p.suffix.lower() not in VIDEO_SUFFIXES:
        raise StressbotsError(f"give a folder of .png frames or a video ({', '.join(VIDEO_SUFFIXES)})", source=str(p))
    cap = cv2.VideoCapture(str(p))
    if not cap.isOpened():
        raise StressbotsError("OpenCV cannot open this video", source=str(p))
    count = int(cap.get(cv2.CAP_PROP_FRAME_COUNT) or -1)

    def video() -> Iterator[tuple[str, np.ndarray]]:
        k = 0
        try:
            while True:
                ok, img = cap.read()
                if not ok:
                    break
                yield f"{k}", _grey(img)
                k += 1
        finally:
            cap.release()
        if k == 0:
            raise StressbotsError("the video has no readable frames", source=str(p))

    return count, video()
