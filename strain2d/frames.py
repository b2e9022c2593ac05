"""Frame sources: video files, multi-page TIFF, image folders, image lists.

Frames are yielded one at a time as ``(H, W)`` float32 gray images in the
source's own intensity units; a video is streamed, never loaded whole.  The
pixel convention is x = column, y = row, with the centre of the top-left pixel
at (0, 0).
"""

from __future__ import annotations

import logging
import os
import re
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np

from strain2d.errors import SourceError

__all__ = ["IMAGE_SUFFIXES", "VIDEO_SUFFIXES", "EndFrames", "FrameSource", "open_frames", "to_gray"]

VIDEO_SUFFIXES = frozenset(
    {".mp4", ".avi", ".mov", ".mkv", ".m4v", ".wmv", ".mpg", ".mpeg", ".webm", ".ogv", ".3gp"}
)
TIFF_SUFFIXES = frozenset({".tif", ".tiff"})
IMAGE_SUFFIXES = frozenset({".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".jp2", ".webp"})


def _video_capture(path: Path):
    """An OpenCV capture whose messages on opening do not reach the terminal.

    OpenCV's AVI reader prints what it finds wrong in a damaged header straight
    to the process's stderr ("Unexpected element. Expected: LIST. Got: ..."),
    and its FFmpeg backend logs a codec it cannot open ("[ERROR:0@0.022] ...");
    FFmpeg itself prints lines about damaged frames ("Slice pointer chain
    broken").  The toolkit reports the problem itself, in one line: what OpenCV
    printed while opening goes to the log (``-v`` shows it); set
    ``OPENCV_FFMPEG_LOGLEVEL`` (e.g. 24) to see FFmpeg's.

    OpenCV converts the name to UTF-8 and crashes the process on one that is not
    (``vid\\xe9o.avi`` from a Latin-1 drive): such a video is opened through a
    UTF-8 alias (:func:`tissue_core.filenames.utf8_alias`); the capture keeps
    the file open once it has opened it.
    """
    import cv2

    from tissue_core.filenames import utf8_alias
    from tissue_core.images import caught_stderr

    os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")  # AV_LOG_QUIET
    with utf8_alias(path) as name, caught_stderr() as said:
        cap = cv2.VideoCapture(str(name))
    if said[0]:
        logging.getLogger(__name__).info("OpenCV on opening %s: %s", path, said[0])
    return cap


def _natural_key(path: Path) -> list:
    return [int(s) if s.isdigit() else s.lower() for s in re.split(r"(\d+)", path.name)]


def to_gray(image: np.ndarray, *, order: str = "rgb") -> np.ndarray:
    """Convert an ``(H, W)``, ``(H, W, 3)`` or ``(H, W, 4)`` image to float32 gray.

    Uses ITU-R BT.601 luma weights; ``order`` is ``"rgb"`` or ``"bgr"`` (OpenCV).
    Gray data stored in three equal channels is returned exactly.
    """
    image = np.asarray(image)
    if image.ndim == 2:
        return image.astype(np.float32)
    if image.ndim == 3 and image.shape[2] in (3, 4):
        c = image[..., :3]
        if np.array_equal(c[..., 0], c[..., 1]) and np.array_equal(c[..., 0], c[..., 2]):
            return c[..., 0].astype(np.float32)  # gray stored as colour (most videos)
        w = np.array([0.299, 0.587, 0.114], dtype=np.float32)
        if order == "bgr":
            w = w[::-1]
        return (image[..., :3].astype(np.float32) @ w).astype(np.float32)
    if image.ndim == 3 and image.shape[2] == 1:
        return image[..., 0].astype(np.float32)
    raise SourceError(f"cannot convert an image of shape {image.shape} to gray")


def _dtype_range(dtype: np.dtype) -> tuple[float, float] | None:
    """(0, 255) for 8-bit data; None where the range must come from the data."""
    if np.dtype(dtype) == np.uint8:
        return 0.0, 255.0
    return None


def _data_range(frame: np.ndarray, dtype: np.dtype | None) -> tuple[float, float]:
    """The first frame's range widened by a quarter of its span on each side
    (clipped to an integer dtype's limits), so later, brighter or darker frames
    keep their contrast when converted to 8 bits; 10- and 12-bit data stored in
    16 bits keep all their gray levels' worth of contrast."""
    lo, hi = float(np.min(frame)), float(np.max(frame))
    span = hi - lo if hi > lo else 1.0
    lo, hi = lo - 0.25 * span, hi + 0.25 * span
    if dtype is not None and np.issubdtype(dtype, np.integer):
        info = np.iinfo(dtype)
        lo, hi = max(lo, float(info.min)), min(hi, float(info.max))
    return lo, hi


def _check_finite(frame: np.ndarray, where: Path, index: int) -> None:
    """Refuse a frame with infinite or NaN pixels (float TIFFs can hold them).

    The trackers' gray-level models and their 8-bit conversion (see
    :attr:`FrameSource.value_range`) have no value for them: one such pixel,
    far from every point, can make all the points of its frame lost.
    """
    if np.isfinite(np.add.reduce(frame, axis=None, dtype=np.float64)):
        return  # the sum of float32 values in float64 is finite exactly when every value is
    nan = np.isnan(frame)
    inf = np.isinf(frame)
    n_nan, n_inf = int(nan.sum()), int(inf.sum())
    what = " and ".join(f"{n} {kind}" for n, kind in ((n_inf, "infinite"), (n_nan, "NaN")) if n)
    y, x = np.argwhere(nan | inf)[0]
    raise SourceError(
        f"{where}: frame {index} holds {what} pixel value{'s' if n_nan + n_inf > 1 else ''} "
        f"(the first at x={x}, y={y}); the trackers need finite gray values: replace them "
        "(e.g. by their neighbours' values) or leave the frame out (--start, --stop)"
    )


class FrameSource:
    """A lazy, re-iterable sequence of gray frames.

    Parameters
    ----------
    sources : sequence of path-like
        One video file, one multi-page TIFF, one folder of images, or several
        image files in frame order.
    start, stop, step : int, keyword-only
        Frame range (Python slice semantics on the source's frames).

    Attributes
    ----------
    kind : {"video", "tiff", "images"}
    names : list of str
        Input file names, for provenance.
    shape : (int, int)
        Frame height and width in pixels.
    frame_range : dict
        ``{"start", "stop", "step"}`` as given (``stop`` None: to the end).
    value_range : (float, float)
        Intensity range mapped to 0-255 for trackers that work on 8-bit images,
        the same for every frame: (0, 255) for 8-bit sources, else the first
        frame's range widened by a quarter of its span on each side.

    Raises
    ------
    SourceError
        Missing, unreadable or empty sources.
    """

    def __init__(
        self,
        sources: Sequence[str | os.PathLike] | str | os.PathLike,
        *,
        start: int = 0,
        stop: int | None = None,
        step: int = 1,
    ) -> None:
        if isinstance(sources, str | os.PathLike):
            sources = [sources]
        paths = [Path(s) for s in sources]
        if not paths:
            raise SourceError("no frame source given")
        for p in paths:
            if not p.exists():
                raise SourceError(f"no such file or folder: {p}")
        if step < 1:
            raise SourceError(f"--step must be >= 1, got {step}")
        if start < 0 or (stop is not None and stop < 0):
            raise SourceError("frame range start and stop must be >= 0")
        self._slice = slice(start, stop, step)
        self.frame_range = {"start": start, "stop": stop, "step": step}
        if len(paths) == 1 and paths[0].is_dir():
            files = sorted(
                (f for f in paths[0].iterdir() if f.suffix.lower() in IMAGE_SUFFIXES),
                key=_natural_key,
            )
            if not files:
                raise SourceError(f"folder {paths[0]} holds no images")
            self.kind, self._paths = "images", files
        elif len(paths) == 1 and paths[0].suffix.lower() in VIDEO_SUFFIXES:
            self.kind, self._paths = "video", paths
        elif len(paths) == 1 and paths[0].suffix.lower() in TIFF_SUFFIXES:
            self.kind, self._paths = "tiff", paths
        else:
            bad = [p for p in paths if p.is_dir() or p.suffix.lower() not in IMAGE_SUFFIXES]
            if bad:
                raise SourceError(f"not an image, video or TIFF stack: {bad[0]}")
            self.kind, self._paths = "images", paths
        self.names = [str(p) for p in paths]
        self._n_source = self._count()
        self._indices = range(self._n_source)[self._slice]
        if len(self._indices) == 0:
            raise SourceError("the frame range selects no frame")
        first = next(iter(self))
        self.shape = first.shape
        self.value_range = self._raw_range or _data_range(first, self._dtype)

    # -- source-specific readers -------------------------------------------------
    def _count(self) -> int:
        self._raw_range = None
        self._dtype = None
        if self.kind == "video":
            import cv2

            cap = _video_capture(self._paths[0])
            try:
                if not cap.isOpened():
                    raise SourceError(f"cannot read video {self._paths[0]}")
                ok, frame = cap.read()
                if not ok:
                    raise SourceError(f"cannot read any frame from video {self._paths[0]}")
                self._dtype = frame.dtype
                self._raw_range = _dtype_range(frame.dtype)
                n = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
            finally:
                cap.release()
            return n if n > 0 else self._count_video_frames()
        if self.kind == "tiff":
            import tifffile

            from tissue_core.tiff_files import check_complete, tifffile_messages

            try:
                with tifffile_messages() as messages, tifffile.TiffFile(self._paths[0]) as tif:
                    n = len(tif.pages)
                    series = tif.series[0]
                    # a file cut short reads as fewer frames: refused as truncated instead
                    check_complete(tif, series, str(self._paths[0]), messages)
                    axes = dict(zip(series.axes, series.shape, strict=True))
                    self._dtype = np.dtype(tif.pages[0].dtype)
                    self._raw_range = _dtype_range(self._dtype)
            except SourceError:
                raise
            except Exception as exc:  # tifffile raises many types on corrupt files
                raise SourceError(f"cannot read TIFF {self._paths[0]}: {exc}") from None
            if axes.get("C", 1) > 1:
                raise SourceError(
                    f"{self._paths[0]} has {axes['C']} channels (axes {''.join(axes)}); "
                    "save the channel to track as its own TIFF"
                )
            return n
        image = self._read_image(self._paths[0])
        self._dtype = image.dtype
        self._raw_range = _dtype_range(image.dtype)
        return len(self._paths)

    def _count_video_frames(self) -> int:
        cap = _video_capture(self._paths[0])
        n = 0
        while cap.grab():
            n += 1
        cap.release()
        return n

    @staticmethod
    def _read_image(path: Path) -> np.ndarray:
        from tissue_core.images import read_image

        return read_image(path)  # whole, or refused in one line (a cut JPEG is not gray rows)

    def _iter_raw(self) -> Iterator[np.ndarray]:
        wanted = self._indices
        if self.kind == "video":
            import cv2

            cap = _video_capture(self._paths[0])
            try:
                if wanted.start:
                    cap.set(cv2.CAP_PROP_POS_FRAMES, wanted.start)
                i = wanted.start
                while i < wanted.stop:
                    ok, frame = cap.read()
                    if not ok:
                        raise SourceError(
                            f"{self._paths[0]}: frame {i} of the {self._n_source} the video "
                            "announces cannot be decoded (the file is truncated or damaged; "
                            f"--stop {i} uses the frames before it)"
                        )
                    if (i - wanted.start) % wanted.step == 0:
                        yield to_gray(frame, order="bgr")
                    i += 1
            finally:
                cap.release()
        elif self.kind == "tiff":
            import tifffile

            from tissue_core.tiff_files import tifffile_messages

            with tifffile_messages(), tifffile.TiffFile(self._paths[0]) as tif:
                for i in wanted:
                    try:
                        page = tif.pages[i].asarray()
                    except Exception as exc:  # tifffile raises many types on damaged files
                        raise SourceError(
                            f"{self._paths[0]}: frame {i} cannot be read (the file is truncated "
                            f"or damaged: {exc})"
                        ) from None
                    yield to_gray(page)
        else:
            for i in wanted:
                yield to_gray(self._read_image(self._paths[i]), order="bgr")

    # -- public interface --------------------------------------------------------
    def __iter__(self) -> Iterator[np.ndarray]:
        shape = getattr(self, "shape", None)
        for k, frame in enumerate(self._iter_raw()):
            where = self._paths[self._indices[k]] if self.kind == "images" else self._paths[0]
            if shape is not None and frame.shape != shape:
                raise SourceError(
                    f"{where}: frame {k} has size {frame.shape[1]}x{frame.shape[0]}, "
                    f"the reference frame {shape[1]}x{shape[0]}"
                )
            _check_finite(frame, where, self._indices[k])
            yield frame

    def __len__(self) -> int:
        """Number of selected frames (from the container's frame count for videos)."""
        return len(self._indices)

    def first(self) -> np.ndarray:
        """The reference frame."""
        return next(iter(self))

    def frame(self, index: int) -> np.ndarray:
        """One selected frame by index (negative counts from the end)."""
        n = len(self)
        if not -n <= index < n:
            raise IndexError(f"frame {index} out of range for {n} frames")
        index %= n
        for k, frame in enumerate(self):
            if k == index:
                return frame
        raise SourceError(f"frame {index} could not be read")

    def read_all(self) -> np.ndarray:
        """All selected frames as one ``(T, H, W)`` float32 array."""
        return np.stack(list(self))

    def __repr__(self) -> str:
        return (
            f"FrameSource({self.kind}, {len(self)} frames of {self.shape[1]}x{self.shape[0]} px, "
            f"from {self.names[0]}{' ...' if len(self.names) > 1 else ''})"
        )


def open_frames(
    sources: Sequence[str | os.PathLike] | str | os.PathLike,
    *,
    start: int = 0,
    stop: int | None = None,
    step: int = 1,
    min_frames: int = 2,
) -> FrameSource:
    """Open a frame source and check it holds at least ``min_frames`` frames.

    See :class:`FrameSource` for the accepted sources.
    """
    source = FrameSource(sources, start=start, stop=stop, step=step)
    if len(source) < min_frames:
        raise SourceError(
            f"{source.names[0]} gives {len(source)} frame(s); at least {min_frames} are needed "
            "(a reference frame and a deformed one)"
        )
    return source


class EndFrames:
    """A frame source that keeps its first and last frames as it is iterated, and every
    frame too when they fit ``keep_bytes``.

    Trackers stream through a source once; wrapping it lets the caller use the
    reference and the final frame afterwards (for figures) without decoding the
    video again.  With ``keep_bytes``, a pass that reads every frame also keeps
    them, as 8-bit images, when each one's values are whole numbers in 0..255
    (an 8-bit video, gray or gray stored as colour) and all of them together fit
    that many bytes: iterating again (the animation of ``strain2d analyze``)
    then gives the same frames, as float32, without decoding the video a second
    time.  Other sources (colour, 16-bit, too long) are decoded again as before.
    Everything else (``len``, ``shape``, ``value_range``, ...) is the wrapped
    source's.

    Attributes
    ----------
    first, last : (H, W) float32 or None
        Set once iteration has reached them.
    """

    def __init__(self, source: FrameSource, *, keep_bytes: int = 0) -> None:
        self.source = source
        self.first: np.ndarray | None = None
        self.last: np.ndarray | None = None
        self.keep_bytes = int(keep_bytes)
        self._kept: list[np.ndarray] | None = None
        self._keeping = False  # a pass is keeping the frames now

    def __len__(self) -> int:
        return len(self.source)

    def __getattr__(self, name: str):
        return getattr(self.source, name)

    @property
    def kept(self) -> bool:
        """Whether every frame is kept (a second pass decodes nothing)."""
        return self._kept is not None

    def __iter__(self) -> Iterator[np.ndarray]:
        if self._kept is not None:
            for frame in self._kept:
                yield frame.astype(np.float32)
            return
        n = len(self.source)
        h, w = self.source.shape
        # 8-bit sources only: their gray values lie in 0..255 (whole, unless mixed from colour);
        # one pass at a time keeps them (a tracker's reader thread and a second pass beside it
        # would each hold a copy)
        eight_bit = tuple(self.source.value_range) == (0.0, 255.0)
        keeping, mine = None, False
        if eight_bit and 0 < n * h * w <= self.keep_bytes and not self._keeping:
            keeping, self._keeping, mine = [], True, True
        try:
            for k, frame in enumerate(self.source):
                if k == 0:
                    self.first = frame
                self.last = frame
                if keeping is not None:
                    small = frame.astype(np.uint8)
                    if np.array_equal(small, frame):
                        keeping.append(small)
                    else:  # mixed from colour: not kept, decoded again
                        keeping = None
                yield frame
            if keeping is not None and len(keeping) == n:
                self._kept = keeping
        finally:
            if mine:
                self._keeping = False

    def ends(self) -> tuple[np.ndarray, np.ndarray]:
        """First and last frames, read from the source if iteration did not reach them."""
        first = self.first if self.first is not None else self.source.first()
        last = self.last if self.last is not None else self.source.frame(-1)
        return first, last
