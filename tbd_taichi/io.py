"""Frame input: ``.npy``, ``.npz``, video files and image folders, as float32 frames.

Two ways in:

* :func:`read_frames` loads a whole sequence as a float32 array (T, H, W);
* :func:`iter_frames` streams it one float32 (H, W) frame at a time, so a long
  video or a memory-mapped ``.npy`` is never loaded whole; :func:`prefetched` decodes
  ahead in a second thread while the caller works on the current frame.

Frames keep their raw values (8-bit, 14-bit or float); normalisation to unit
noise is :mod:`tbd_taichi.normalize`'s job.  Colour images and videos are
converted to grey with OpenCV.  Every bad input raises :class:`InputError` with
the path and the problem.
"""
from __future__ import annotations

import os
import queue
import re
import struct
import threading
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterator

import cv2
import numpy as np

from .errors import InputError

VIDEO_SUFFIXES = (".mp4", ".avi", ".mov", ".mkv", ".m4v", ".wmv", ".mpg", ".mpeg", ".webm")
IMAGE_SUFFIXES = (".png", ".tif", ".tiff", ".bmp")
ARRAY_SUFFIXES = (".npy", ".npz")
F32_MAX = float(np.finfo(np.float32).max)
SUPPORTED = "a .npy or .npz file (array 'frames'), a video (" + ", ".join(VIDEO_SUFFIXES) + \
    ") or a folder of " + "/".join(s.lstrip(".").upper() for s in IMAGE_SUFFIXES) + " images"


@dataclass
class FrameSource:
    """A sequence that can be streamed: its name, frame shape (H, W) and length.

    ``n_frames`` is exact for arrays and folders; for videos it is the container's
    own count, which some codecs only estimate (None when unknown).  ``kind``: "array", "video" or
    "folder"; ``dtype``: the frames' type as stored (before the float32 conversion); ``fps``: a video's
    frame rate (None when it has none).
    """

    name: str
    shape: tuple[int, int]
    n_frames: int | None
    _open: Callable[[], Iterator[np.ndarray]]
    kind: str = "array"
    dtype: np.dtype = np.dtype(np.float32)
    fps: float | None = None

    def __iter__(self) -> Iterator[np.ndarray]:
        for index, frame in enumerate(self._open()):
            yield checked_frame(frame, self.name, index, self.shape)


def natural_key(name: str) -> list:
    """Sort key that orders 'f2.png' before 'f10.png'."""
    return [int(part) if part.isdigit() else part.lower() for part in re.split(r"(\d+)", name)]


def to_grey(image: np.ndarray, where: str) -> np.ndarray:
    """(H, W) grey image from a grey, BGR or BGRA image (OpenCV channel order)."""
    if image.ndim == 2:
        return image
    if image.ndim == 3 and image.shape[2] in (3, 4):
        code = cv2.COLOR_BGR2GRAY if image.shape[2] == 3 else cv2.COLOR_BGRA2GRAY
        if image.dtype not in (np.uint8, np.uint16, np.float32):
            image = image.astype(np.float32)
        return cv2.cvtColor(image, code)
    if image.ndim == 3 and image.shape[2] == 1:
        return image[:, :, 0]
    raise InputError(f"{where}: image has shape {image.shape}; expected (H, W) grey or (H, W, 3|4) colour")


def _check_dtype(dtype: np.dtype, where: str) -> None:
    if dtype.kind not in "iuf":
        raise InputError(f"{where}: dtype {dtype} is not a real number type; expected an integer or float array")


def checked_frame(frame: np.ndarray, where: str, index: int, shape: tuple[int, int] | None = None) -> np.ndarray:
    """One frame as C-contiguous float32 (H, W); rejects other shapes and NaN/inf."""
    frame = np.asarray(frame)
    _check_dtype(frame.dtype, where)
    if frame.ndim != 2:
        raise InputError(f"{where}: frame {index} has {frame.ndim} dimensions {frame.shape}; expected a 2-D (H, W) frame")
    if shape is not None and frame.shape != tuple(shape):
        raise InputError(f"{where}: frame {index} has size {frame.shape[0]}x{frame.shape[1]} (HxW); "
                         f"expected {shape[0]}x{shape[1]} like the first frame")
    out = np.ascontiguousarray(frame, dtype=np.float32)
    if not np.isfinite(out).all():
        bad = "NaN" if np.isnan(out).any() else "inf"
        raise InputError(f"{where}: frame {index} contains {bad} values")
    return out


def stream_frame(frame, shape: tuple[int, int], index: int, owner: str) -> np.ndarray:
    """Frame ``index`` handed to a streaming ``owner`` (tracker, extractor) as float32, checked for
    its shape and for NaN/inf."""
    frame = np.asarray(frame)
    if frame.dtype.kind not in "iuf":
        raise InputError(f"frame {index} has dtype {frame.dtype}; the {owner} takes integer or float frames")
    if frame.shape != tuple(shape):
        raise InputError(f"frame {index} has shape {frame.shape}; the {owner} was built for {tuple(shape)}")
    if not np.isfinite(frame).all():
        raise InputError(f"frame {index} contains NaN or inf")
    return np.ascontiguousarray(frame, dtype=np.float32)


def _array_source(array: np.ndarray, name: str) -> FrameSource:
    _check_dtype(array.dtype, name)
    if array.ndim != 3:
        raise InputError(f"{name}: array has {array.ndim} dimensions {array.shape}; expected 3 dimensions (T, H, W)")
    if array.shape[1] < 1 or array.shape[2] < 1:
        raise InputError(f"{name}: frames of size {array.shape[1]}x{array.shape[2]} are empty")
    _check_finite(array, name)
    return FrameSource(name, (int(array.shape[1]), int(array.shape[2])), int(array.shape[0]), lambda: iter(array),
                       dtype=array.dtype)


def _check_finite(array: np.ndarray, name: str, chunk: int = 64) -> None:
    """A float array's first frame holding NaN or inf, as an InputError before any work (chunks of frames: no
    whole-array temporary)."""
    if array.dtype.kind != "f":
        return
    wide = array.dtype.itemsize > 4  # float64 frames become float32: values past its range would become inf
    for start in range(0, len(array), chunk):
        part = array[start:start + chunk]
        # |x| ≤ F32_MAX is false for NaN and inf as well: one pass tests all three
        finite = (np.abs(part) <= F32_MAX if wide else np.isfinite(part)).all(axis=(1, 2))
        if not finite.all():
            index = start + int(np.argmin(finite))
            frame = array[index]
            what = "NaN" if np.isnan(frame).any() else "inf" if np.isinf(frame).any() else \
                f"values beyond float32's range (±{F32_MAX:.3g})"
            raise InputError(f"{name}: frame {index} contains {what}")


def _load_array(path: Path) -> np.ndarray:
    try:
        if path.suffix.lower() == ".npy":
            with open(path, "rb") as handle:
                if handle.read(6) != b"\x93NUMPY":
                    raise InputError(f"{path}: not a readable .npy file (no NumPy header)")
            return np.load(path, mmap_mode="r", allow_pickle=False)
        with np.load(path, allow_pickle=False) as archive:
            if "frames" not in archive.files:
                raise InputError(f"{path}: .npz file has no array 'frames' (it has: {', '.join(archive.files) or 'nothing'})")
            return archive["frames"]
    except InputError:
        raise
    except (ValueError, OSError, EOFError, zipfile.BadZipFile) as exc:
        raise InputError(f"{path}: not a readable {path.suffix} file ({exc})") from None


def _video_source(path: Path) -> FrameSource:
    capture = cv2.VideoCapture(str(path))
    ok, first = capture.read() if capture.isOpened() else (False, None)
    count = int(capture.get(cv2.CAP_PROP_FRAME_COUNT)) if ok else 0
    fps = float(capture.get(cv2.CAP_PROP_FPS)) if ok else 0.0
    capture.release()
    if not ok or first is None:
        raise InputError(f"{path}: unreadable video (OpenCV could not decode a frame)")
    shape = to_grey(first, str(path)).shape

    def frames() -> Iterator[np.ndarray]:
        cap = cv2.VideoCapture(str(path))
        try:
            while True:
                ok, image = cap.read()
                if not ok:
                    return
                yield to_grey(image, str(path))
        finally:
            cap.release()

    return FrameSource(str(path), shape, count if count > 0 else None, frames, kind="video", dtype=first.dtype,
                       fps=fps if 0 < fps < 1000 else None)


def _read_image(path: Path) -> np.ndarray:
    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise InputError(f"{path}: unreadable image")
    return to_grey(image, str(path))


def header_size(path: Path) -> tuple[int, int] | None:
    """(H, W) of a PNG or BMP image from its header (its first 26 bytes), None for other types; a file whose
    header does not match its .png or .bmp name is an InputError.  Lets a folder's sizes be checked before the run
    without decoding every image."""
    suffix = path.suffix.lower()
    if suffix not in (".png", ".bmp"):
        return None
    try:
        with open(path, "rb") as handle:
            head = handle.read(26)
    except OSError as exc:
        raise InputError(f"{path}: cannot be read ({exc.strerror})") from None
    if suffix == ".png" and head[:8] == b"\x89PNG\r\n\x1a\n" and head[12:16] == b"IHDR" and len(head) >= 24:
        width, height = struct.unpack(">II", head[16:24])
        return int(height), int(width)
    if suffix == ".bmp" and head[:2] == b"BM" and len(head) >= 26:
        width, height = struct.unpack("<ii", head[18:26])
        return abs(int(height)), int(width)
    raise InputError(f"{path}: unreadable image (not a {suffix.lstrip('.').upper()} file)")


def _check_folder_sizes(files: list, shape: tuple) -> None:
    """Every PNG and BMP of ``files`` as large as the first image (``shape``), from their headers."""
    for index, file in enumerate(files):
        size = header_size(file)
        if size is not None and size != tuple(shape[:2]):
            raise mixed_sizes(file, index, size, shape, files[0])


def mixed_sizes(file: Path, index: int, size, shape, first: Path) -> InputError:
    """The error for image ``index`` of a folder whose (H, W) ``size`` differs from the first image's."""
    return InputError(f"{file}: image {index} has size {size[0]}x{size[1]} (HxW); expected {shape[0]}x{shape[1]} "
                      f"like {first.name}; images of mixed sizes")


def _folder_source(path: Path) -> FrameSource:
    files = sorted((p for p in path.iterdir() if p.is_file() and p.suffix.lower() in IMAGE_SUFFIXES),
                   key=lambda p: natural_key(p.name))
    if not files:
        raise InputError(f"{path}: folder holds no {'/'.join(IMAGE_SUFFIXES)} images")
    first = _read_image(files[0])
    shape = first.shape
    _check_folder_sizes(files, shape)

    def frames() -> Iterator[np.ndarray]:
        for index, file in enumerate(files):
            image = _read_image(file)
            if image.shape != shape:
                raise mixed_sizes(file, index, image.shape, shape, files[0])
            yield image

    return FrameSource(str(path), shape, len(files), frames, kind="folder", dtype=first.dtype)


def open_frames(source) -> FrameSource:
    """A streaming :class:`FrameSource` for a path (file or folder) or an array (T, H, W)."""
    if isinstance(source, FrameSource):
        return source
    if isinstance(source, np.ndarray):
        return _array_source(source, "input array")
    if not isinstance(source, (str, os.PathLike)):
        raise InputError(f"input of type {type(source).__name__} is not a path or an array (T, H, W)")
    path = Path(source)
    if not path.exists():
        raise InputError(f"{path}: no such file or folder")
    if path.is_dir():
        return _folder_source(path)
    suffix = path.suffix.lower()
    if suffix not in ARRAY_SUFFIXES + VIDEO_SUFFIXES + IMAGE_SUFFIXES:
        raise InputError(f"{path}: unknown file type {suffix or '(no suffix)'!r}; expected {SUPPORTED}")
    if path.stat().st_size == 0:
        raise InputError(f"{path}: file is empty")
    if suffix in ARRAY_SUFFIXES:
        return _array_source(_load_array(path), str(path))
    if suffix in VIDEO_SUFFIXES:
        return _video_source(path)
    raise InputError(f"{path}: a single image is one frame; pass the folder that holds the sequence")


def _too_few(name: str, n: int, min_frames: int) -> InputError:
    return InputError(f"{name}: {n} frame(s), but at least {min_frames} are needed")


def check_length(src: FrameSource, min_frames: int = 1) -> None:
    """An InputError if ``src`` is known to hold fewer than ``min_frames`` frames (a video's own count is only an
    estimate: it is checked as it streams)."""
    if src.n_frames is not None and src.n_frames < max(min_frames, 1) and src.kind != "video":
        raise _too_few(src.name, src.n_frames, max(min_frames, 1))


def iter_frames(source, min_frames: int = 1) -> Iterator[np.ndarray]:
    """Stream float32 (H, W) frames from ``source`` (see :func:`open_frames`).

    Raises :class:`InputError` before the first frame when the length is known to be
    short, otherwise when the stream ends short.
    """
    src = open_frames(source)
    check_length(src, min_frames)
    count = 0
    for frame in src:
        count += 1
        yield frame
    if count < min_frames:
        raise _too_few(src.name, count, min_frames)


def read_frames(source, min_frames: int = 1) -> np.ndarray:
    """Load a whole sequence as float32 (T, H, W); see :func:`open_frames` for the inputs."""
    src = open_frames(source)
    frames = list(iter_frames(src, min_frames))
    if not frames:
        raise _too_few(src.name, 0, max(min_frames, 1))
    return np.stack(frames)


PREFETCH_FRAMES = 32  # frames decoded ahead by prefetched(): 2.6 MiB at 320 × 256 float32
_END = object()


def prefetched(frames: Iterator[np.ndarray], depth: int = PREFETCH_FRAMES) -> Iterator[np.ndarray]:
    """``frames``, decoded up to ``depth`` frames ahead in a daemon thread (OpenCV's decoder and NumPy's casts
    release the GIL, so decoding overlaps the caller's work on a second core).  The same frames in the same
    order; an error raised while decoding is raised here, at the frame where it happened; a caller that stops
    early stops the decoder."""
    ahead: queue.Queue = queue.Queue(maxsize=max(int(depth), 1))
    stop = threading.Event()

    def put(item) -> bool:
        while not stop.is_set():
            try:
                ahead.put(item, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def decode() -> None:
        try:
            for frame in frames:
                if not put(frame):
                    return
            put(_END)
        except BaseException as exc:  # noqa: BLE001 - handed to the consumer, raised there
            put(exc)
        finally:
            getattr(frames, "close", lambda: None)()  # a stopped generator releases its file or video now

    worker = threading.Thread(target=decode, name="frame-decoder", daemon=True)
    worker.start()
    try:
        while True:
            item = ahead.get()
            if item is _END:
                return
            if isinstance(item, BaseException):
                raise item
            yield item
    finally:
        stop.set()
        worker.join()
