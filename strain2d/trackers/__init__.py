"""Point trackers behind one interface, found through a small registry.

A tracker is a function::

    track(frames, points, *, progress=None, **options) -> Tracks

``frames`` is an iterable of ``(H, W)`` gray frames (frame 0 is the
reference, e.g. a :class:`strain2d.frames.FrameSource`), ``points`` the
``(N, 2)`` reference positions in pixels.  Each tracker registers itself in
its own module of this package with :func:`register_tracker`; modules here are
discovered automatically, so adding a tracker touches one file.
"""

from __future__ import annotations

import importlib
import pkgutil
from collections.abc import Callable
from dataclasses import dataclass

from strain2d.errors import InputError

__all__ = ["TrackerSpec", "available_trackers", "get_tracker", "register_tracker"]


@dataclass(frozen=True)
class TrackerSpec:
    """A registered tracker.

    Attributes
    ----------
    name : str
    function : callable
    description : str
    needs_frames : bool
        False for trackers that read tracks made elsewhere.
    needs_model : bool
        True for trackers that need code or weights from outside the package
        (``cotracker3``); the benchmark leaves them out unless named.
    """

    name: str
    function: Callable
    description: str
    needs_frames: bool = True
    needs_model: bool = False


_REGISTRY: dict[str, TrackerSpec] = {}
_discovered = False


def register_tracker(
    name: str, *, description: str, needs_frames: bool = True, needs_model: bool = False
) -> Callable:
    """Decorator registering a tracker function under ``name``."""

    def decorate(function: Callable) -> Callable:
        if name in _REGISTRY and _REGISTRY[name].function is not function:
            raise ValueError(f"a tracker named {name!r} is already registered")
        _REGISTRY[name] = TrackerSpec(name, function, description, needs_frames, needs_model)
        return function

    return decorate


def _discover() -> None:
    global _discovered
    if not _discovered:
        for module in pkgutil.iter_modules(__path__):
            if not module.name.startswith("_"):
                importlib.import_module(f"{__name__}.{module.name}")
        _discovered = True


def available_trackers() -> dict[str, TrackerSpec]:
    """All registered trackers by name."""
    _discover()
    return dict(sorted(_REGISTRY.items()))


def get_tracker(name: str) -> TrackerSpec:
    """The tracker registered as ``name``; raises :class:`InputError` if unknown."""
    trackers = available_trackers()
    if name not in trackers:
        raise InputError(f"unknown tracker {name!r}; choose from {', '.join(trackers)}")
    return trackers[name]
