"""Point trackers behind one interface, found through a small registry.

A tracker is a function::

    track(frames, points, *, progress=None, **options) -> Tracks

``frames`` is an iterable of ``(H, W)`` gray frames (frame 0 is the
reference, e.g. a :class:`strain2d.frames.FrameSource`), ``points`` the
``(N, 2)`` reference positions in pixels.  Each tracker registers itself in
its own module of this package with :func:`register_tracker`, declaring the
options it offers on the command line (:class:`TrackerOption`); modules here
are discovered automatically, and :func:`add_tracker_arguments` turns the
declarations into flags, so adding a tracker touches one file.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from strain2d.errors import InputError

__all__ = [
    "TrackerOption",
    "TrackerSpec",
    "add_tracker_arguments",
    "available_trackers",
    "get_tracker",
    "register_tracker",
    "tracker_inputs",
    "tracker_options",
]


@dataclass(frozen=True)
class TrackerOption:
    """An option a tracker offers on the command line.

    Attributes
    ----------
    name : str
        The tracker function's keyword argument.
    flag : str
        The command-line flag, e.g. ``"--subset"``; trackers that share an
        option share its flag.
    help : str
        What it does for this tracker; ``(default ...)`` is added from the
        function's default unless the text says it.
    type : callable, optional
        Turns the text given into the value (``int``, ``float``, or a function
        raising ``ValueError`` with a message); None for switches.
    choices : tuple of str, optional
    switch : bool or None
        A flag without a value that sets the option to this (``True``, or
        ``False`` for a ``--no-...`` flag).
    metavar : str, optional
    is_file : bool
        The value names a file or folder the command reads (it may not be
        overwritten by an output).
    """

    name: str
    flag: str
    help: str
    type: Callable[[str], object] | None = str
    choices: tuple[str, ...] | None = None
    switch: bool | None = None
    metavar: str | None = None
    is_file: bool = False

    @property
    def dest(self) -> str:
        return self.flag.lstrip("-").replace("-", "_")

    def convert(self, text: str, tracker: str) -> object:
        """The value of ``text`` for this option, or an :class:`InputError` naming the flag."""
        if self.choices is not None and text not in self.choices:
            raise InputError(
                f"{self.flag} {text} does not apply to the {tracker} tracker: choose "
                f"{', '.join(self.choices)}"
            )
        try:
            return self.type(text)
        except (ValueError, argparse.ArgumentTypeError) as exc:
            what = {int: "a whole number", float: "a number"}.get(self.type)
            reason = f"must be {what}, got {text!r}" if what else str(exc)
            raise InputError(f"{self.flag} {reason}") from None


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
    options : tuple of TrackerOption
        The options it offers on the command line.
    group : str, optional
        A heading for its options in ``--help`` (e.g. what it needs installed);
        options it shares with other trackers are listed with theirs.
    """

    name: str
    function: Callable
    description: str
    needs_frames: bool = True
    needs_model: bool = False
    options: tuple[TrackerOption, ...] = ()
    group: str | None = None


_REGISTRY: dict[str, TrackerSpec] = {}
_discovered = False


def register_tracker(
    name: str,
    *,
    description: str,
    needs_frames: bool = True,
    needs_model: bool = False,
    options: Sequence[TrackerOption] = (),
    group: str | None = None,
) -> Callable:
    """Decorator registering a tracker function under ``name`` with its command-line options."""

    def decorate(function: Callable) -> Callable:
        if name in _REGISTRY and _REGISTRY[name].function is not function:
            raise ValueError(f"a tracker named {name!r} is already registered")
        import inspect

        accepted = inspect.signature(function).parameters
        for option in options:
            if option.name not in accepted:
                raise ValueError(f"tracker {name!r} has no parameter {option.name!r}")
        _REGISTRY[name] = TrackerSpec(
            name, function, description, needs_frames, needs_model, tuple(options), group
        )
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


def _flags(trackers: dict[str, TrackerSpec]) -> dict[str, list[tuple[str, TrackerOption]]]:
    """Each flag with the trackers that offer it, checked to agree on its kind."""
    flags: dict[str, list[tuple[str, TrackerOption]]] = {}
    for spec in trackers.values():
        for option in spec.options:
            flags.setdefault(option.flag, []).append((spec.name, option))
    for flag, offered in flags.items():
        if len({option.switch for _, option in offered}) > 1:
            raise ValueError(f"trackers disagree on whether {flag} takes a value")
    return flags


def _default(spec: TrackerSpec, option: TrackerOption, defaults: dict | None):
    """The value a tracker uses when the option is not given (a command's own, or its own)."""
    import inspect

    own = (defaults or {}).get(spec.name, {})
    if option.name in own:
        return own[option.name]
    value = inspect.signature(spec.function).parameters[option.name].default
    return None if value is inspect.Parameter.empty else value


def _help(spec: TrackerSpec, option: TrackerOption, defaults: dict | None) -> str:
    value = _default(spec, option, defaults)
    if "default" in option.help or option.switch is not None or value is None:
        return option.help
    return f"{option.help} (default {value})"


def add_tracker_arguments(
    parser: argparse.ArgumentParser,
    trackers: Sequence[str] | None = None,
    *,
    defaults: dict[str, dict] | None = None,
    notes: dict[str, str] | None = None,
) -> None:
    """Add the command-line flags that the trackers declare (default: every tracker).

    A flag offered by several trackers is added once, its help naming what
    it does for each; values stay text until :func:`tracker_options` turns
    them into the chosen tracker's.  ``defaults`` ({tracker: {option: value}})
    are a command's own defaults, shown in the help; pass the same to
    :func:`tracker_options`.  ``notes`` ({flag: text}) add a command's own
    advice to a flag's help (e.g. why its default differs).
    """
    specs = available_trackers()
    if trackers is not None:
        specs = {name: specs[name] for name in trackers}
    general = parser.add_argument_group("tracker options (each says which trackers take it)")
    groups = {}
    for flag, offered in _flags(specs).items():
        names = {tracker for tracker, _ in offered}
        own = specs[offered[0][0]].group if len(names) == 1 else None
        target = general
        if own:
            target = groups.get(own) or groups.setdefault(own, parser.add_argument_group(own))
        first = offered[0][1]
        text = "; ".join(
            f"{tracker}: {_help(specs[tracker], option, defaults)}" for tracker, option in offered
        )
        if notes and flag in notes:
            text += f". {notes[flag]}"
        text = text.replace("%", "%%")
        if first.switch is not None:
            target.add_argument(
                flag,
                dest=first.dest,
                action="store_const",
                const=first.switch,
                default=None,
                help=text,
            )
        else:
            choices = sorted({c for _, o in offered for c in (o.choices or ())}) or None
            target.add_argument(
                flag, dest=first.dest, default=None, metavar=first.metavar, help=text,
                choices=choices,
            )  # fmt: skip


def tracker_options(
    args: argparse.Namespace, tracker: str, *, defaults: dict[str, dict] | None = None
) -> dict:
    """The options given on the command line for ``tracker``, as its keyword arguments.

    ``defaults`` ({tracker: {option: value}}) fill in what was not given.

    Raises
    ------
    InputError
        A flag given that the tracker does not offer, or a value it cannot take.
    """
    spec = get_tracker(tracker)
    own = {option.flag: option for option in spec.options}
    options = dict((defaults or {}).get(tracker, {}))
    for flag, offered in _flags(available_trackers()).items():
        value = getattr(args, offered[0][1].dest, None)
        if value is None:
            continue
        if flag not in own:
            takers = ", ".join(name for name, _ in offered)
            raise InputError(
                f"{flag} does not apply to the {tracker} tracker (an option of {takers})"
            )
        option = own[flag]
        options[option.name] = (
            value if option.switch is not None else option.convert(value, tracker)
        )
    return options


def tracker_inputs(args: argparse.Namespace) -> list[str]:
    """The files and folders named by tracker options given on the command line."""
    return [
        value
        for offered in _flags(available_trackers()).values()
        for _, option in offered[:1]
        if option.is_file and (value := getattr(args, option.dest, None))
    ]
