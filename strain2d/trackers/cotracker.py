"""``cotracker3``: Meta's pretrained point tracker CoTracker3 (offline model).

The paper tracks its virtual grid zero-shot with CoTracker3 [1]_.  Its code and
weights are published under a non-commercial licence (CC BY-NC 4.0) and are not
on the package index, so this module does not ship them; it calls them:

* ``repo``: a local clone of https://github.com/facebookresearch/co-tracker,
  loaded with ``torch.hub.load(repo, "cotracker3_offline", source="local",
  pretrained=False)``;
* ``checkpoint``: a state dict such as ``scaled_offline.pth``, read with
  ``torch.load(..., weights_only=True)`` into that model;
* or an installed ``cotracker`` package (``cotracker.predictor.CoTrackerPredictor``);
* ``download=True`` lets ``torch.hub`` fetch whatever of the code and weights
  is not given.  Nothing is downloaded without it.

Any object honouring the published predictor's contract can be passed as
``predictor`` instead: called as ``predictor(video, queries=q)`` with ``video``
a float tensor ``(B, T, 3, H, W)`` holding values 0-255 and ``q`` a float
tensor ``(B, N, 3)`` of ``(t, x, y)`` (frame index within ``video``, pixel
coordinates of ``video``), it returns tracks ``(B, T, N, 2)`` in the same pixel
coordinates and visibility ``(B, T, N)`` (bool, or a probability), optionally
followed by a confidence ``(B, T, N)``.  The published predictor resizes every
frame to 384 x 512 internally (``interp_shape``), maps coordinates with
``align_corners=True`` (pixel centres at integer coordinates, the toolkit's
convention), and its offline model was trained on 60-frame windows.

What this adapter adds:

* **Region-of-interest crop.**  The model sees every frame at 384 x 512
  pixels whatever the video's size, so a grid that covers a small part of a
  large frame is tracked at a small fraction of the camera's resolution.
  With ``crop=True`` the frames are cut to the points' bounding box widened by
  ``crop_margin`` times its size on each side and then to the model's 4:3
  aspect ratio (within the frame), and coordinates are shifted back.  One
  model pixel then spans ``crop width / 512`` video pixels instead of
  ``frame width / 512``; ``Tracks.meta["options"]["model_pixels_per_px"]``
  records the scale used.  The margin must hold the tissue's motion: points
  that leave the crop are tracked outside the model's view.
* **Chunks in time.**  ``chunk_frames`` frames at a time (default 60, the
  offline window), consecutive chunks sharing ``chunk_overlap`` frames.  Each
  point is queried again in the next chunk at the last frame of the overlap
  where it was visible (its last reliable position), or at the overlap's last
  frame if it was hidden throughout; frames up to the query keep the earlier
  chunk's result.  Only one chunk of frames is held in memory.
* **Chunks of points.**  At most ``query_chunk`` points per model call.
* Gray frames scaled to 0-255 by the source's ``value_range`` and replicated
  to 3 channels; ``device`` (CUDA when present, else CPU); ``half=True``
  runs the model under float16 autocast on CUDA; ``progress(done, total)``
  after each chunk.

``visible`` is the predictor's visibility (a probability above
``visibility_threshold`` when it returns probabilities); ``quality`` is the
visibility times the confidence when the predictor returns one.  The
published predictor thresholds visibility x confidence at 0.6 itself and
returns booleans, so its ``quality`` is 1 (visible) or 0.

References
----------
.. [1] Karaev, N., Makarov, I., Wang, J., Neverova, N., Vedaldi, A., &
   Rupprecht, C. (2024). CoTracker3: Simpler and better point tracking by
   pseudo-labelling real videos. arXiv:2410.11831.
   https://doi.org/10.48550/arXiv.2410.11831
"""

from __future__ import annotations

import importlib
import logging
import os
from collections.abc import Callable, Iterable
from contextlib import nullcontext
from pathlib import Path
from typing import Any

import numpy as np

from strain2d.errors import InputError
from strain2d.trackers import TrackerOption, register_tracker
from strain2d.tracks import Tracks

__all__ = ["MODEL_INPUT_SIZE", "crop_box", "load_cotracker3", "track_cotracker"]

log = logging.getLogger(__name__)

#: (height, width) the published predictor resizes every frame to.
MODEL_INPUT_SIZE = (384, 512)
#: Frames of the offline model's window.
MODEL_WINDOW = 60
REPO_URL = "https://github.com/facebookresearch/co-tracker"
WEIGHTS_URL = "https://huggingface.co/facebook/cotracker3/resolve/main/scaled_offline.pth"
HUB_REPO = "facebookresearch/co-tracker"
HUB_ENTRY = "cotracker3_offline"

_HOW_TO_GET = (
    f"clone {REPO_URL}, download {WEIGHTS_URL}, and pass --cotracker-repo DIR "
    "--cotracker-checkpoint scaled_offline.pth (or --cotracker-download to let torch.hub "
    "fetch them)"
)


def _one_line(exc: BaseException) -> str:
    text = str(exc).strip().splitlines()
    return f"{type(exc).__name__}: {text[0] if text else ''}".rstrip(": ")


def _import_torch():
    try:
        import torch
    except ImportError:
        raise InputError(
            "the cotracker3 tracker needs PyTorch: pip install 'tissue-strain[torch]' "
            "(or make setup-torch)"
        ) from None
    return torch


def _read_checkpoint(torch, checkpoint: Path) -> dict:
    try:
        state = torch.load(checkpoint, map_location="cpu", weights_only=True)
    except Exception as exc:  # torch.load raises many types on foreign or corrupt files
        raise InputError(f"cannot read the checkpoint {checkpoint}: {_one_line(exc)}") from None
    if isinstance(state, dict) and isinstance(state.get("model"), dict):
        state = state["model"]  # training checkpoints wrap the weights
    if not (isinstance(state, dict) and state and all(torch.is_tensor(v) for v in state.values())):
        raise InputError(f"{checkpoint} holds no state dict (a mapping of names to tensors)")
    return state


def _load_weights(torch, predictor, state: dict, checkpoint: Path) -> None:
    """Load ``state`` into ``predictor.model`` (the published layout) or the predictor."""
    target = getattr(predictor, "model", None)
    if not isinstance(target, torch.nn.Module):
        target = predictor
    if not isinstance(target, torch.nn.Module):
        raise InputError(f"cannot load {checkpoint}: the predictor is not a torch module")
    try:
        missing, unexpected = target.load_state_dict(state, strict=False)
    except RuntimeError as exc:  # shape mismatches
        raise InputError(f"{checkpoint} does not fit the model: {_one_line(exc)}") from None
    if missing or unexpected:
        parts = [
            f"{len(keys)} {what} (e.g. {keys[0]})"
            for what, keys in (("missing", missing), ("unexpected", unexpected))
            if keys
        ]
        raise InputError(f"{checkpoint} does not fit the model: weights {', '.join(parts)}")


def _package_predictor(cls):
    """``CoTrackerPredictor`` of an installed ``cotracker`` package, without weights."""
    import inspect

    params = inspect.signature(cls).parameters
    kwargs: dict[str, Any] = {"checkpoint": None}
    if "window_len" in params:
        kwargs["window_len"] = MODEL_WINDOW
    if "offline" in params:
        kwargs["offline"] = True
    if "v2" in params:
        kwargs["v2"] = False
    return cls(**kwargs)


def _load(
    torch,
    *,
    repo: str | os.PathLike | None,
    checkpoint: str | os.PathLike | None,
    download: bool,
) -> tuple[Any, dict]:
    """(predictor, provenance) from the sources described in the module docstring."""
    info: dict[str, Any] = {}
    ckpt = None
    if checkpoint is not None:
        ckpt = Path(checkpoint).expanduser()
        if ckpt.is_dir():
            raise InputError(
                f"--cotracker-checkpoint {ckpt} is a folder; give the weights file in it "
                "(e.g. scaled_offline.pth)"
            )
        if not ckpt.is_file():
            raise InputError(
                f"no such CoTracker3 checkpoint: {ckpt} (download it from {WEIGHTS_URL})"
            )
        info["checkpoint"] = str(ckpt)
    no_weights = (
        "{where} gives CoTracker3's code but not its weights: download "
        f"{WEIGHTS_URL} and add --cotracker-checkpoint FILE, or --cotracker-download"
    )
    if repo is not None:
        root = Path(repo).expanduser()
        if not root.is_dir():
            raise InputError(f"--cotracker-repo {root} is not a folder; git clone {REPO_URL}")
        if not (root / "hubconf.py").is_file():
            raise InputError(f"{root} has no hubconf.py; give the root of a clone of {REPO_URL}")
        if ckpt is None and not download:
            raise InputError(no_weights.format(where=f"--cotracker-repo {root}"))
        try:
            predictor = torch.hub.load(
                str(root), HUB_ENTRY, source="local", pretrained=ckpt is None
            )
        except Exception as exc:  # whatever the repository's code raises
            raise InputError(f"cannot load {HUB_ENTRY} from {root}: {_one_line(exc)}") from None
        info.update(code="repository", repo=str(root))
    else:
        try:
            cls = importlib.import_module("cotracker.predictor").CoTrackerPredictor
        except (ImportError, AttributeError):
            cls = None
        if cls is not None:
            if ckpt is None and not download:
                raise InputError(no_weights.format(where="the installed cotracker package"))
            try:
                predictor = _package_predictor(cls)
                if ckpt is None:
                    state = torch.hub.load_state_dict_from_url(WEIGHTS_URL, map_location="cpu")
                    _load_weights(torch, predictor, state, Path(WEIGHTS_URL))
                    info["weights"] = WEIGHTS_URL
            except InputError:
                raise
            except Exception as exc:
                raise InputError(f"cannot build CoTrackerPredictor: {_one_line(exc)}") from None
            info.update(code="cotracker package", module=cls.__module__)
        elif download:
            try:
                predictor = torch.hub.load(
                    HUB_REPO, HUB_ENTRY, trust_repo=True, pretrained=ckpt is None
                )
            except Exception as exc:
                raise InputError(f"cannot download {HUB_REPO}: {_one_line(exc)}") from None
            info.update(code=f"torch.hub {HUB_REPO}")
        elif ckpt is not None:
            raise InputError(
                f"--cotracker-checkpoint holds the weights only; the model's code comes from "
                f"--cotracker-repo DIR (git clone {REPO_URL}) or an installed cotracker package"
            )
        else:
            raise InputError(
                f"the cotracker3 tracker needs CoTracker3's code and weights: {_HOW_TO_GET}"
            )
    if ckpt is not None:
        _load_weights(torch, predictor, _read_checkpoint(torch, ckpt), ckpt)
    elif "weights" not in info:
        info["weights"] = "torch.hub download (pretrained=True)"
    return predictor, info


def load_cotracker3(
    *,
    repo: str | os.PathLike | None = None,
    checkpoint: str | os.PathLike | None = None,
    download: bool = False,
):
    """Load the CoTracker3 offline predictor once, to reuse across videos.

    Parameters
    ----------
    repo : path, keyword-only
        A local clone of https://github.com/facebookresearch/co-tracker.
    checkpoint : path, keyword-only
        Weights such as ``scaled_offline.pth`` (``torch.load(weights_only=True)``).
    download : bool, keyword-only
        Allow ``torch.hub`` to download the code and/or weights not given.

    Returns
    -------
    predictor
        Pass it as ``predictor=`` to :func:`track_cotracker`.

    Raises
    ------
    InputError
        PyTorch missing, code or weights missing or unusable; the message says
        how to get them.
    """
    return _load(_import_torch(), repo=repo, checkpoint=checkpoint, download=download)[0]


def _device(torch, device: str | None, half: bool):
    if device in (None, "auto"):
        device = "cuda" if torch.cuda.is_available() else "cpu"
    try:
        dev = torch.device(device)
    except (RuntimeError, TypeError):
        raise InputError(f"--device must be cpu, cuda or cuda:N, got {device!r}") from None
    if dev.type == "cuda":
        if not torch.cuda.is_available():
            raise InputError(f"--device {device}: PyTorch {torch.__version__} sees no CUDA device")
        if dev.index is not None and dev.index >= torch.cuda.device_count():
            raise InputError(f"--device {device}: only {torch.cuda.device_count()} CUDA device(s)")
    elif dev.type != "cpu":
        raise InputError(f"--device must be cpu, cuda or cuda:N, got {device!r}")
    if half and dev.type != "cuda":
        raise InputError(
            "--half (float16) needs a CUDA device; on the CPU the model runs in float32"
        )
    return dev


def crop_box(
    points: np.ndarray,
    frame_shape: tuple[int, int],
    *,
    margin: float = 0.5,
    aspect: float = MODEL_INPUT_SIZE[1] / MODEL_INPUT_SIZE[0],
) -> tuple[int, int, int, int]:
    """The region handed to the model: the points' box, a margin, the model's aspect ratio.

    Parameters
    ----------
    points : (N, 2) float
        Reference positions (x, y) in pixels.
    frame_shape : (H, W)
    margin : float, keyword-only
        Added on each side, as a fraction of the box's width and height.
    aspect : float, keyword-only
        Width / height the box is widened to (where the frame allows), so the
        model's resize scales x and y alike.

    Returns
    -------
    (x0, y0, x1, y1) : int
        Column and row bounds, ``x1`` and ``y1`` exclusive, inside the frame.

    Examples
    --------
    >>> crop_box(np.array([[100.0, 100.0], [199.0, 199.0]]), (800, 800), margin=0.5)
    (17, 50, 283, 250)
    """
    points = np.asarray(points, dtype=float).reshape(-1, 2)
    if not (np.isfinite(margin) and margin >= 0):
        raise InputError(f"--crop-margin must be a number >= 0, got {margin}")
    h, w = frame_shape
    lo, hi = points.min(axis=0), points.max(axis=0)
    size = np.maximum(hi - lo, 16.0)  # a box of nearly aligned points still gets context
    centre = (lo + hi) / 2
    half = size * (0.5 + margin)
    if half[0] < aspect * half[1]:
        half[0] = aspect * half[1]
    else:
        half[1] = half[0] / aspect
    limit = np.array([w - 1, h - 1], dtype=float)
    half = np.minimum(half, limit / 2)
    centre = np.clip(centre, half, limit - half)  # slide the box into the frame
    x0, y0 = np.floor(centre - half).astype(int)
    x1, y1 = np.ceil(centre + half).astype(int) + 1
    return int(x0), int(y0), int(min(x1, w)), int(min(y1, h))


def _to_model_range(frame: np.ndarray, value_range: tuple[float, float]) -> np.ndarray:
    lo, hi = value_range
    if lo == 0.0 and hi == 255.0:
        return np.clip(frame, 0.0, 255.0).astype(np.float32, copy=False)
    scaled = (np.asarray(frame, dtype=np.float32) - lo) * np.float32(255.0 / (hi - lo))
    return np.clip(scaled, 0.0, 255.0)


def _call(predictor, torch, video, queries, *, autocast) -> tuple[np.ndarray, ...]:
    """One model call: (tracks (T, n, 2), visibility (T, n), confidence (T, n) or None)."""
    with torch.inference_mode(), autocast():
        out = predictor(video, queries=queries)
    if not isinstance(out, tuple | list) or len(out) < 2:
        raise InputError("the CoTracker3 predictor must return (tracks, visibility[, confidence])")
    T, n = video.shape[1], queries.shape[1]
    arrays = []
    names = ("tracks", "visibility", "confidence")
    shapes = ((1, T, n, 2), (1, T, n), (1, T, n))
    for name, value, shape in zip(names, out[:3], shapes, strict=False):  # confidence optional
        value = value.detach().to("cpu")
        if tuple(value.shape) != shape:
            raise InputError(
                f"the CoTracker3 predictor returned {name} of shape {tuple(value.shape)}, "
                f"expected {shape}"
            )
        arrays.append(value[0].numpy() if value.dtype == torch.bool else value[0].float().numpy())
    return arrays[0], arrays[1], arrays[2] if len(arrays) > 2 else None


#: bytes per pixel of each frame of a chunk in this process's memory: the frame scaled to
#: float32, and the chunk stacked into one array for the model (a lower bound: the model's own
#: copies, on the CPU, come on top)
CHUNK_BYTES_PER_PIXEL = 2 * 4


def _check_chunk_fits(chunk_frames: int, total: int | None, size: tuple[int, int]) -> None:
    """Refuse, before the model runs, a chunk of frames that cannot fit the memory."""
    from tissue_core.resources import check_fits

    frames = chunk_frames if total is None else min(chunk_frames, total)
    w, h = size
    check_fits(
        f"--chunk-frames {chunk_frames} ({frames} frames of {w}x{h} px in each model call)",
        memory=frames * w * h * CHUNK_BYTES_PER_PIXEL,
        remedy="use fewer --chunk-frames, or keep the crop around the points",
    )


@register_tracker(
    "cotracker3",
    description="Meta's pretrained CoTracker3 (offline); needs PyTorch and its code and weights",
    needs_model=True,
    group="cotracker3 (needs PyTorch: make setup-torch; see docs/strain2d.md)",
    options=[
        TrackerOption(
            "repo",
            "--cotracker-repo",
            "local clone of facebookresearch/co-tracker",
            metavar="DIR",
            is_file=True,
        ),
        TrackerOption(
            "checkpoint",
            "--cotracker-checkpoint",
            "model weights, e.g. scaled_offline.pth",
            metavar="FILE",
            is_file=True,
        ),
        TrackerOption(
            "download",
            "--cotracker-download",
            "allow torch.hub to download the code and/or weights that are not given",
            switch=True,
        ),
        TrackerOption(
            "device", "--device", "cpu, cuda or cuda:N (default: cuda when present, else cpu)"
        ),
        TrackerOption("half", "--half", "float16 autocast (CUDA only)", switch=True),
        TrackerOption(
            "crop",
            "--no-crop",
            "give the model whole frames instead of the points' region plus a margin",
            switch=False,
        ),
        TrackerOption(
            "crop_margin",
            "--crop-margin",
            "margin around the points' bounding box, as a fraction of its size",
            type=float,
        ),
        TrackerOption("chunk_frames", "--chunk-frames", "frames per model call", type=int),
        TrackerOption(
            "chunk_overlap",
            "--chunk-overlap",
            "frames shared by consecutive chunks",
            type=int,
        ),
        TrackerOption("query_chunk", "--query-chunk", "points per model call", type=int),
    ],
)
def track_cotracker(
    frames: Iterable[np.ndarray],
    points: np.ndarray,
    *,
    predictor: Callable | None = None,
    repo: str | os.PathLike | None = None,
    checkpoint: str | os.PathLike | None = None,
    download: bool = False,
    device: str | None = None,
    half: bool = False,
    crop: bool = True,
    crop_margin: float = 0.5,
    chunk_frames: int = MODEL_WINDOW,
    chunk_overlap: int = 4,
    query_chunk: int = 1024,
    visibility_threshold: float = 0.5,
    value_range: tuple[float, float] | None = None,
    progress: Callable[[int, int | None], None] | None = None,
) -> Tracks:
    """Track points with CoTracker3 (see the module docstring for the model's sources).

    Parameters
    ----------
    frames : iterable of (H, W) float
        Frame 0 is the reference.  A :class:`~strain2d.frames.FrameSource`
        supplies its ``value_range`` and length.
    points : (N, 2) float
        Reference positions (x, y) in pixels.
    predictor : callable, keyword-only
        A loaded predictor (:func:`load_cotracker3`) or any object honouring
        the published contract; then ``repo``, ``checkpoint`` and ``download``
        are not used.
    repo, checkpoint, download : keyword-only
        Where the model comes from (see :func:`load_cotracker3`).
    device : {"cpu", "cuda", "cuda:N"} or None, keyword-only
        None: CUDA when PyTorch sees a GPU, else the CPU.
    half : bool, keyword-only
        Run the model under float16 autocast (CUDA only); coordinates are
        returned in float32.
    crop : bool, keyword-only
        Hand the model only the region :func:`crop_box` gives.
    crop_margin : float, keyword-only
        Margin of that region, as a fraction of the points' bounding box.
    chunk_frames : int, keyword-only
        Frames per model call (>= 2; the offline model's window is 60).
    chunk_overlap : int, keyword-only
        Frames shared by consecutive chunks (1 .. chunk_frames - 1).
    query_chunk : int, keyword-only
        Points per model call.
    visibility_threshold : float, keyword-only
        Visibility probability above which a point counts as visible (used
        only when the predictor returns probabilities rather than booleans).
    value_range : (lo, hi), keyword-only
        Intensity range mapped to 0..255; default the source's, else the
        first frame's min and max.
    progress : callable(done, total), keyword-only
        Called after each chunk of frames with the frames done so far.

    Returns
    -------
    Tracks
        ``meta["options"]`` records the model's source, device, precision,
        crop, chunk sizes and model input size.
    """
    if not (isinstance(chunk_frames, int | np.integer) and chunk_frames >= 2):
        raise InputError(f"--chunk-frames must be an integer >= 2, got {chunk_frames}")
    if not (isinstance(chunk_overlap, int | np.integer) and 1 <= chunk_overlap < chunk_frames):
        raise InputError(
            f"--chunk-overlap must be an integer from 1 to {chunk_frames - 1}, got {chunk_overlap}"
        )
    if not (isinstance(query_chunk, int | np.integer) and query_chunk >= 1):
        raise InputError(f"--query-chunk must be an integer >= 1, got {query_chunk}")
    if not (np.isfinite(crop_margin) and crop_margin >= 0):
        raise InputError(f"--crop-margin must be a number >= 0, got {crop_margin}")
    if not 0 < visibility_threshold < 1:
        raise InputError(
            f"visibility_threshold must be between 0 and 1, got {visibility_threshold}"
        )
    torch = _import_torch()
    dev = _device(torch, device, half)
    if predictor is None:
        predictor, source = _load(torch, repo=repo, checkpoint=checkpoint, download=download)
    else:
        source = {"code": f"given predictor {type(predictor).__name__}"}
    if isinstance(predictor, torch.nn.Module):
        predictor = predictor.to(dev).eval()
    interp = tuple(getattr(predictor, "interp_shape", MODEL_INPUT_SIZE))

    points = np.asarray(points, dtype=float).reshape(-1, 2)
    n_points = len(points)
    total = len(frames) if hasattr(frames, "__len__") else None
    if value_range is None:
        value_range = getattr(frames, "value_range", None)
    if value_range is None and isinstance(frames, np.ndarray) and frames.dtype == np.uint8:
        value_range = (0.0, 255.0)
    it = iter(frames)
    try:
        ref = np.asarray(next(it))
    except StopIteration:
        raise InputError("no frames to track") from None
    if value_range is None:
        lo, hi = float(ref.min()), float(ref.max())
        value_range = (lo, hi if hi > lo else lo + 1.0)
    value_range = (float(value_range[0]), float(value_range[1]))
    h, w = ref.shape
    if crop:
        x0, y0, x1, y1 = crop_box(points, (h, w), margin=crop_margin, aspect=interp[1] / interp[0])
    else:
        x0, y0, x1, y1 = 0, 0, w, h
    _check_chunk_fits(chunk_frames, total, (x1 - x0, y1 - y0))
    offset = np.array([x0, y0], dtype=float)

    def prepare(frame: np.ndarray) -> np.ndarray:
        frame = np.asarray(frame)
        if frame.shape != (h, w):
            raise InputError(f"frame of shape {frame.shape}, expected {(h, w)} like frame 0")
        return _to_model_range(frame[y0:y1, x0:x1], value_range)

    autocast = (
        (lambda: torch.autocast(device_type="cuda", dtype=torch.float16)) if half else nullcontext
    )
    positions = [points.copy()]
    visible = [np.ones(n_points, dtype=bool)]
    quality = [np.ones(n_points)]
    query_t = np.zeros(n_points, dtype=int)  # absolute frame of each point's query
    query_xy = points.copy()
    buffer, start, exhausted = [prepare(ref)], 0, False
    n_calls = n_chunks = 0
    while True:
        while len(buffer) < chunk_frames and not exhausted:
            try:
                buffer.append(prepare(next(it)))
            except StopIteration:
                exhausted = True
        end = start + len(buffer)
        if end <= len(positions):  # nothing new: the video ended with the overlap
            break
        gray = torch.from_numpy(np.stack(buffer)).to(dev)
        video = gray[None, :, None].expand(1, len(buffer), 3, *gray.shape[1:]).contiguous()
        new = slice(len(positions) - start, len(buffer))
        chunk_pos = np.empty((new.stop - new.start, n_points, 2))
        chunk_vis = np.empty((new.stop - new.start, n_points), dtype=bool)
        chunk_q = np.empty((new.stop - new.start, n_points))
        for first in range(0, n_points, query_chunk):
            idx = slice(first, min(first + query_chunk, n_points))
            q = np.column_stack([query_t[idx] - start, query_xy[idx] - offset])
            queries = torch.from_numpy(q.astype(np.float32))[None].to(dev)
            tr, vis, conf = _call(predictor, torch, video, queries, autocast=autocast)
            n_calls += 1
            p = vis.astype(float) if conf is None else vis.astype(float) * np.clip(conf, 0, 1)
            seen = vis if vis.dtype == bool else p > visibility_threshold
            chunk_pos[:, idx] = tr[new] + offset
            chunk_vis[:, idx] = seen[new]
            chunk_q[:, idx] = np.clip(p[new], 0.0, 1.0)
        del video, gray
        n_chunks += 1
        for k in range(len(chunk_pos)):
            pos = chunk_pos[k]
            finite = np.all(np.isfinite(pos), axis=1)
            positions.append(np.where(finite[:, None], pos, positions[-1]))
            visible.append(chunk_vis[k] & finite)
            quality.append(np.where(finite, chunk_q[k], 0.0))
        log.info("cotracker3: frames %d-%d tracked (%d model calls)", start, end - 1, n_calls)
        if progress:
            progress(end, total)
        if exhausted:
            break
        # next chunk: re-query each point at its last visible frame of the overlap
        start = end - chunk_overlap
        buffer = buffer[-chunk_overlap:]
        query_t[:] = end - 1
        for f in range(start, end):
            query_t[visible[f]] = f
        query_xy = np.stack([positions[f][i] for i, f in enumerate(query_t)])
    if len(positions) < 2:
        raise InputError("tracking needs at least 2 frames")
    options = {
        **{k: str(v) for k, v in (("repo", repo), ("checkpoint", checkpoint)) if v is not None},
        "download": bool(download),
        "model": source,
        "device": str(dev),
        "dtype": "float16 (autocast)" if half else "float32",
        "crop": bool(crop),
        "crop_margin": float(crop_margin) if crop else None,
        "crop_box_px": [x0, y0, x1, y1],
        "model_input_size": [int(interp[0]), int(interp[1])],
        "model_pixels_per_px": [(interp[1] - 1) / (x1 - x0 - 1), (interp[0] - 1) / (y1 - y0 - 1)],
        "chunk_frames": int(chunk_frames),
        "chunk_overlap": int(chunk_overlap),
        "query_chunk": int(query_chunk),
        "visibility_threshold": float(visibility_threshold),
        "value_range": list(value_range),
        "time_chunks": n_chunks,
        "model_calls": n_calls,
    }
    return Tracks(
        np.stack(positions),
        np.stack(visible),
        np.stack(quality),
        {"tracker": "cotracker3", "options": options},
    )
