"""``python -m mpm3d`` on broken, hostile and conflicting input: every command ends with one
line naming the file or option and the problem (exit 2), leaves its inputs and anything of the
user's byte-identical, and writes nothing; Ctrl-C during a real run ends with exit 130 and no
output (see :mod:`tests.badinput`).

Stacks that are unusual but valid (big-endian, every pixel type, NaN voxels) are accepted:
they are tested in ``test_stack_types.py``, not here."""

from __future__ import annotations

import os
import signal
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
import tifffile

import tissue_core.resources as resources
from mpm3d.cli import main
from tests.badinput import (
    FAMILIES,
    WRITING,
    assert_inert,
    assert_refused,
    interrupt,
    killed,
    scratch_left,
    snapshot,
    stale_scratch,
    unwritable_folder,
    write,
)
from tests.filenames import assert_ran, assert_refused_process, latin1, shown, strict_json
from tissue_core.outputs import atomic_dir

COMMANDS = ("analyze", "compare")
CASES: list = []


def run(argv: list[str]) -> int:
    """``main``, with argparse's own refusals (SystemExit) as an exit status too."""
    try:
        return main(argv)
    except SystemExit as exc:
        return exc.code


def case(name: str, *commands: str):
    """Register ``COMMAND-FAMILY-CASE`` for each of ``commands`` (default: both).

    The decorated function of ``(stack, tmp)`` returns the options to change and the
    fragments the error line must hold (the file or option, and the problem), or None for
    input that is accepted (the ``formula`` family: see :func:`tests.badinput.assert_inert`).
    ``batch`` is named explicitly: it runs ``analyze``, whose cases hold for it too.
    """
    assert any(name.startswith(f"{family}-") for family in FAMILIES), name

    def register(build: Callable[[Path, Path], tuple[dict, list[str]]]):
        for command in commands or COMMANDS:
            CASES.append(pytest.param(command, build, id=f"{command}-{name}"))
        return build

    return register


def base(command: str, stack: Path, tmp: Path) -> dict:
    """The options of a command line that would run; positionals under ``_N`` keys."""
    if command == "analyze":
        return {"_1": stack, "--out": tmp / "out", "--no-figures": True, "-q": True}
    if command == "batch":
        return {"_1": stack, "--out": tmp / "out", "--no-figures": True, "--workers": "1",
                "-q": True}  # fmt: skip
    return {"_1": stack, "_2": stack, "--out": tmp / "out", "--no-figures": True, "-q": True}


def command_line(command: str, options: dict) -> list[str]:
    argv = [command]
    for key, value in options.items():
        if value is None or value is False:
            continue
        if key.startswith("_"):
            argv.append(str(value))
        elif value is True:
            argv.append(key)
        else:
            argv += [key, str(value)]
    return argv


# --------------------------------------------------------------------------- broken files


def cut(source: Path, tmp: Path, fraction: float, name: str = "cut.tif") -> Path:
    """The first ``fraction`` of ``source``'s bytes (a copy cut short by a full disk)."""
    data = source.read_bytes()
    return write(tmp, name, data[: int(len(data) * fraction)])


def imagej(tmp: Path, name: str, data: np.ndarray, axes: str = "ZCYX", **kwargs) -> Path:
    path = tmp / name
    metadata = {"axes": axes, "spacing": 4.0, "unit": "um"}
    tifffile.imwrite(path, data, imagej=True, resolution=(0.2, 0.2), metadata=metadata, **kwargs)
    return path


def ome(tmp: Path, name: str, data: np.ndarray) -> Path:
    path = tmp / name
    metadata = {"axes": "ZCYX", "PhysicalSizeZ": 4.0, "PhysicalSizeY": 5.0, "PhysicalSizeX": 5.0}
    tifffile.imwrite(path, data, ome=True, photometric="minisblack", metadata=metadata)
    return path


def stack_data(stack: Path) -> np.ndarray:
    return tifffile.imread(stack)


def user_folder(tmp: Path, name: str = "out") -> Path:
    folder = tmp / name
    folder.mkdir()
    write(folder, "thesis.tex", "the work of years")
    return folder


def earlier_result(tmp: Path, *, user_file: bool) -> Path:
    folder = tmp / "out"
    with atomic_dir(folder) as result:
        write(result, "metrics.json", "{}\n")
    if user_file:
        write(folder, "my_notes.txt", "added by the user afterwards")
    return folder


# ---- missing


@case("missing-stack-file")
def _(s, t):
    return {"_1": t / "gone.tif"}, ["gone.tif", "not found"]


@case("missing-stack-folder")
def _(s, t):
    return {"_1": t / "no" / "such" / "stack.tif"}, ["stack.tif", "not found"]


@case("missing-after-stack", "compare")
def _(s, t):
    return {"_2": t / "gone.tif"}, ["after stack", "gone.tif", "not found"]


# ---- empty


@case("empty-zero-byte-file")
def _(s, t):
    return {"_1": write(t, "empty.tif", b"")}, ["empty.tif", "empty (0 bytes)"]


@case("empty-zero-byte-after-stack", "compare")
def _(s, t):
    return {"_2": write(t, "empty.tif", b"")}, ["after stack", "empty.tif", "empty (0 bytes)"]


@case("empty-all-zero-stack")
def _(s, t):
    path = imagej(t, "zeros.tif", np.zeros((8, 2, 16, 16), np.uint16))
    return {"_1": path}, ["zeros.tif", "uniform", "no surface"]


@case("empty-tiff-without-pages")
def _(s, t):
    header = b"II*\x00" + (8).to_bytes(4, "little") + b"\x00\x00" + b"\x00" * 4  # no IFD entries
    return {"_1": write(t, "nopages.tif", header)}, ["nopages.tif", "holds no images"]


# ---- truncated


@case("truncated-half-file")
def _(s, t):
    return {"_1": cut(s, t, 0.5)}, ["cut.tif", "truncated", "ImageJ metadata announces"]


@case("truncated-60-percent")
def _(s, t):
    return {"_1": cut(s, t, 0.6)}, ["cut.tif", "truncated"]


@case("truncated-header")
def _(s, t):
    return {"_1": cut(s, t, 0.0001)}, ["cut.tif", "truncated"]


@case("truncated-ome")
def _(s, t):
    full = ome(t, "full.ome.tif", stack_data(s))
    return {"_1": cut(full, t, 0.5, "cut.ome.tif")}, ["cut.ome.tif", "truncated"]


@case("truncated-compressed")
def _(s, t):
    full = imagej(t, "full.tif", stack_data(s), compression="zlib")
    return {"_1": cut(full, t, 0.6)}, ["cut.tif", "truncated"]


@case("truncated-plain-pages")
def _(s, t):
    full = t / "pages.tif"
    tifffile.imwrite(full, stack_data(s)[:, 1], photometric="minisblack", metadata=None)
    return {"_1": cut(full, t, 0.5), "--spacing": "4,5,5"}, ["cut.tif", "truncated"]


@case("truncated-after-stack", "compare")
def _(s, t):
    return {"_2": cut(s, t, 0.5)}, ["after stack", "cut.tif", "truncated"]


# ---- wrong type


@case("wrong-type-text-as-tif")
def _(s, t):
    return {"_1": write(t, "notes.tif", "not an image\n")}, ["notes.tif", "not a TIFF"]


@case("wrong-type-png-as-tif")
def _(s, t):
    png = b"\x89PNG\r\n\x1a\n" + b"\x00" * 64
    return {"_1": write(t, "image.tif", png)}, ["image.tif", "not a TIFF"]


@case("wrong-type-folder-as-stack")
def _(s, t):
    (t / "stack.tif").mkdir()
    return {"_1": t / "stack.tif"}, ["stack.tif", "is a folder"]


@case("wrong-type-one-page")
def _(s, t):
    path = t / "slice.tif"
    tifffile.imwrite(path, stack_data(s)[10, 1])
    return {"_1": path}, ["slice.tif", "2D image", "not a z-stack"]


@case("wrong-type-rgb")
def _(s, t):
    path = t / "rgb.tif"
    tifffile.imwrite(path, np.zeros((4, 16, 16, 3), np.uint8), photometric="rgb")
    return {"_1": path}, ["rgb.tif", "RGB"]


@case("wrong-type-time-series")
def _(s, t):
    path = imagej(t, "movie.tif", np.zeros((3, 5, 16, 16), np.uint16), axes="TZYX")
    return {"_1": path}, ["movie.tif", "time axis"]


@case("wrong-type-text-as-after-stack", "compare")
def _(s, t):
    return {"_2": write(t, "notes.tif", "not an image\n")}, ["after stack", "notes.tif"]


# ---- stack content


@case("stack-complex")
def _(s, t):
    path = t / "fft.tif"
    tifffile.imwrite(path, np.ones((4, 16, 16), np.complex64), photometric="minisblack")
    return {"_1": path}, ["fft.tif", "complex"]


@case("stack-all-nan")
def _(s, t):
    path = imagej(t, "nan.tif", np.full((8, 2, 16, 16), np.nan, np.float32))
    return {"_1": path}, ["nan.tif", "NaN", "no surface"]


@case("stack-two-slices")
def _(s, t):
    path = imagej(t, "thin.tif", stack_data(s)[20:22])
    return {"_1": path}, ["thin.tif", "at least 3 slices"]


@case("stack-nan-after-stack", "compare")
def _(s, t):
    path = imagej(t, "nan.tif", np.full((8, 2, 16, 16), np.nan, np.float32))
    return {"_2": path}, ["after stack", "nan.tif", "NaN"]


# ---- options


OPTIONS = {
    # name: (option, value, fragments)
    "threshold-nan": ("--threshold", "nan", ["--threshold", "finite"]),
    "threshold-inf": ("--threshold", "inf", ["--threshold", "finite"]),
    "threshold-text": ("--threshold", "high", ["--threshold", "'high'"]),
    "threshold-negative": ("--threshold", "-5", ["--threshold", "every voxel"]),
    "threshold-above-every-voxel": ("--threshold", "1e9", ["--threshold", "no surface found"]),
    "smooth-negative": ("--smooth", "-1", ["--smooth", ">= 0"]),
    "smooth-nan": ("--smooth", "nan", ["--smooth", "finite"]),
    "smooth-wider-than-the-field": ("--smooth", "1e9", ["--smooth", "wider than the field"]),
    "iso-bin-zero": ("--iso-bin", "0", ["--iso-bin", ">= 1"]),
    "iso-bin-negative": ("--iso-bin", "-2", ["--iso-bin", ">= 1"]),
    "iso-bin-text": ("--iso-bin", "two", ["--iso-bin", "'two'"]),
    "iso-bin-larger-than-the-stack": ("--iso-bin", "50", ["--iso-bin", "at most 48"]),
    "decimate-one": ("--decimate", "1", ["--decimate", "[0, 1)"]),
    "decimate-negative": ("--decimate", "-0.1", ["--decimate", "[0, 1)"]),
    "decimate-nan": ("--decimate", "nan", ["--decimate", "finite"]),
    "spacing-zero": ("--spacing", "0,1,1", ["--spacing", "'0,1,1'"]),
    "spacing-negative": ("--spacing=-1,1,1", True, ["--spacing", "'-1,1,1'"]),
    "spacing-negative-looks-like-an-option": ("--spacing", "-1,1,1", ["--spacing", "argument"]),
    "spacing-nan": ("--spacing", "nan,1,1", ["--spacing", "'nan,1,1'"]),
    "spacing-two-values": ("--spacing", "4,5", ["--spacing", "'4,5'"]),
    "spacing-text": ("--spacing", "a,b,c", ["--spacing", "'a,b,c'"]),
    "spacing-tiny": ("--spacing", "1e-300,1e-300,1e-300", ["--spacing", "between 0.001"]),
    "spacing-in-metres": ("--spacing", "4e-6,5e-6,5e-6", ["--spacing", "between 0.001"]),
    "channel-out-of-range": ("--channel", "7", ["channel 7 out of range", "2 channels"]),
    "channel-unknown-name": ("--channel", "dapi", ["'dapi' not found", "collagen"]),
    "channel-negative": ("--channel", "-1", ["'-1' not found"]),
    "min-fold-height-negative": ("--min-fold-height", "-1", ["--min-fold-height", ">= 0"]),
    "min-fold-height-inf": ("--min-fold-height", "inf", ["--min-fold-height", "finite"]),
}
for _name, (_option, _value, _fragments) in OPTIONS.items():

    @case(f"option-{_name}")
    def _(s, t, option=_option, value=_value, fragments=_fragments):
        return {option: value}, fragments


@case("option-icp-unknown", "compare")
def _(s, t):
    return {"--icp": "maybe"}, ["--icp", "'maybe'"]


# ---- conflicting options


# ---- options that size an allocation beyond the stack or the memory
@case("allocation-smooth-kernel-wider-than-the-field")
def _(s, t):
    return {"--smooth": "1e12"}, ["--smooth", "1e+12 um", "wider than the field of view"]


@case("allocation-iso-bin-beyond-the-stack")
def _(s, t):
    return {"--iso-bin": "1000000"}, ["--iso-bin", "bin 1000000", "at most 48"]


@case("allocation-memory-limit-beyond-the-memory", "analyze")
def _(s, t):
    said = ["--memory-limit 1024.00GiB reads the stack whole", "of memory", "1 MiB is available"]
    return {"--memory-limit": "1TiB"}, said


#: the memory available, bytes, in the cases that ask for more than there is
SMALL_MEMORY = {"analyze-allocation-memory-limit-beyond-the-memory": 2**20}


@case("conflict-no-surface-with-iso-bin")
def _(s, t):
    return {"--no-surface": True, "--iso-bin": "2"}, ["--iso-bin", "--no-surface"]


@case("conflict-no-surface-with-decimate")
def _(s, t):
    return {"--no-surface": True, "--decimate": "0.5"}, ["--decimate", "--no-surface"]


@case("conflict-icp-on-without-surface", "compare")
def _(s, t):
    return {"--no-surface": True, "--icp": "on"}, ["ICP", "--no-surface"]


# ---- output


@case("output-out-is-the-stack")
def _(s, t):
    return {"--out": s, "--overwrite": True}, ["--out", s.name, "would replace the input"]


@case("output-out-is-the-after-stack", "compare")
def _(s, t):
    after = write(t, "after.tif", s.read_bytes())
    changes = {"_2": after, "--out": after, "--overwrite": True}
    return changes, ["--out", "after.tif", "would replace the input"]


@case("output-out-holds-the-stack")
def _(s, t):
    return {"--out": s.parent, "--overwrite": True}, ["--out", "would replace the input"]


@case("output-existing-user-folder")
def _(s, t):
    return {"--out": user_folder(t)}, ["--out", "not a result of this toolkit"]


@case("output-existing-user-folder-overwrite")
def _(s, t):
    changes = {"--out": user_folder(t), "--overwrite": True}
    return changes, ["--out", "not a result of this toolkit"]


@case("output-earlier-result-without-overwrite")
def _(s, t):
    return {"--out": earlier_result(t, user_file=False)}, ["--out", "--overwrite"]


@case("output-earlier-result-holding-a-user-file")
def _(s, t):
    changes = {"--out": earlier_result(t, user_file=True), "--overwrite": True}
    return changes, ["--out", "my_notes.txt"]


@case("output-existing-file")
def _(s, t):
    return {"--out": write(t, "out", "my notes")}, ["--out", "is a file"]


@case("output-existing-file-overwrite")
def _(s, t):
    return {"--out": write(t, "out", "my notes"), "--overwrite": True}, ["--out", "is a file"]


@case("output-missing-parent-folder")
def _(s, t):
    return {"--out": t / "no" / "such" / "out"}, ["--out", "does not exist"]


@case("output-symbolic-link")
def _(s, t):
    target = user_folder(t, "real")
    (t / "out").symlink_to(target)
    return {"--out": t / "out"}, ["--out", "symbolic link"]


@case("output-read-only-folder")
def _(s, t):
    folder = unwritable_folder(t)
    return {"--out": folder / "out"}, [str(folder), "cannot be written"]


# ---- names too long for a folder: refused before any folder is made


@case("output-name-too-long", "analyze", "compare", "batch")
def _(s, t):
    return {"--out": t / ("x" * 300)}, ["--out", "300 bytes long"]


@case("output-run-name-too-long", "batch")
def _(s, t):
    stack = write(t / "data", "y" * 245 + ".tif", s.read_bytes())
    return {"_1": stack}, [stack.name, "245 bytes long", "at most 241"]


@case("csv-name-too-long", "batch")
def _(s, t):
    manifest = write(t / "data", "stacks.csv", f"stack,name\n{s},{'x' * 300}\n")
    return {"_1": manifest}, ["stacks.csv, line 2", "name", "300 bytes long"]


# ---- names a spreadsheet would run as formulas: accepted, and every CSV written holds them inert


@case("formula-stack-and-out-names", "analyze")
def _(s, t):
    return {"_1": write(t / "data", "=1+2.tif", s.read_bytes()), "--out": t / "-2+3"}, None


@case("formula-stack-and-out-names", "compare")
def _(s, t):
    before = write(t / "data", "=1+2.tif", s.read_bytes())
    after = write(t / "data", "@SUM(A1).tif", s.read_bytes())
    return {"_1": before, "_2": after, "--out": t / "-2+3"}, None


@case("formula-stack-file-name", "batch")
def _(s, t):
    return {"_1": write(t / "data", "-2+3.tif", s.read_bytes())}, None


@case("formula-manifest-names", "batch")
def _(s, t):
    return {"_1": write(t / "data", "stacks.csv", f"stack,name\n{s},@SUM(A1)\n")}, None


def _files(options: dict, out: Path) -> list[Path]:
    """The inputs of a command line: every existing path but the output."""
    paths = [Path(v) for k, v in options.items() if k.startswith("_")]
    return [p for p in paths if p.exists() and p != out]


@pytest.mark.parametrize(("command", "build"), CASES)
def test_bad_input(command, build, mpm_small, tmp_path, capsys, monkeypatch, request):
    memory = SMALL_MEMORY.get(request.node.callspec.id)
    if memory is not None:
        monkeypatch.setattr(resources, "available_memory", lambda: memory)
    stack = tmp_path / "data" / "stack.tif"  # a copy: the case may name its folder
    stack.parent.mkdir()
    stack.write_bytes(mpm_small[0].read_bytes())
    changes, fragments = build(stack, tmp_path)
    options = base(command, stack, tmp_path)
    options.update(changes)
    argv = command_line(command, options)
    out = Path(options["--out"])
    try:
        if fragments is None:  # accepted: see tests.badinput.assert_inert
            assert_inert(run, argv, capsys, out=out, inputs=_files(options, out))
            return
        assert_refused(
            run,
            argv,
            capsys,
            prog="mpm3d",
            fragments=fragments,
            inputs=_files(options, out),
            out=out,
        )
    finally:
        for folder in tmp_path.rglob("*"):  # let pytest remove what a case locked
            if folder.is_dir() and not folder.is_symlink():
                folder.chmod(0o755)


def test_every_command_has_cases_of_every_family_that_applies():
    ids = [p.id for p in CASES] + list(NAME_CASES)
    for command in COMMANDS:
        for family in FAMILIES:
            if family in ("csv", "calibration"):  # mpm3d reads no tables and no cameras
                continue
            if family in ("interrupt", "terminate", "stale"):
                continue  # test_interrupt below
            if family == "nonfinite":  # infinite voxels are read: test_stack_types.py
                continue
            assert any(i.startswith(f"{command}-{family}-") for i in ids), (command, family)


# --------------------------------------------------------------------------- Ctrl-C


#: ``python -c``: run mpm3d with a compiled kernel called over and over for 0.2 s (each call
#: takes milliseconds) and Ctrl-C (``KERNEL:SIGTERM``: SIGTERM) sent 1 ms after the first call
#: starts; it prints how long the calls went on, to show that the signal came while compiled
#: code ran
IN_KERNEL = """
import os, signal, sys, threading, time
import mpm3d._kernels as kernels
name, _, sent_signal = sys.argv[1].partition(":")
real = getattr(kernels, name)
def started(*args):
    # the first call in a process loads the compiled kernel, importing numba's modules: a
    # Ctrl-C there is held until the import ends (the "imports" stage covers that); here it
    # is to land while compiled code runs
    result = real(*args)
    sent = threading.Event()
    def ctrl_c():
        os.kill(os.getpid(), getattr(signal, sent_signal or "SIGINT"))
        sent.set()
    waited = time.perf_counter()
    calls = 0  # calls begun after the Ctrl-C was sent
    try:  # on a busy machine the timer's thread may start late: the kernel is called until it has
        threading.Timer(0.001, ctrl_c).start()  # inside the try: the Ctrl-C may land at once
        while True:
            after_ctrl_c = sent.is_set()
            result = real(*args)
            calls += after_ctrl_c
            if calls > 2 or time.perf_counter() - waited > 60:
                print(f"[kernel {name} not interrupted: {calls} calls]", file=sys.stderr)
                return result
    except KeyboardInterrupt:
        print(f"[kernel {name} interrupted: {calls} calls after the Ctrl-C]", file=sys.stderr)
        raise
setattr(kernels, name, started)
sys.argv = ["mpm3d", *sys.argv[2:]]
import runpy
runpy.run_module("mpm3d", run_name="__main__", alter_sys=True)  # as python -m mpm3d
"""
#: Ctrl-C at a stage of a real run: ``after`` seconds after the step ``when`` was printed
#: (or after the start: the imports), so that it lands there on any machine
STAGES = [
    ("analyze", None, 0.3, "imports"),
    ("analyze", "choosing the channel", 0.1, "reading"),
    ("analyze", "finding the surface", 0.05, "height-map"),
    ("analyze", "building the isosurface", 0.05, "mesh"),
    ("analyze", "writing results", 0.3, "writing"),
    ("compare", "finding the surface", 0.05, "height-map"),
    ("compare", "writing results", 0.2, "writing"),
]
#: SIGTERM (``kill``, ``timeout``, ``scancel``, ``docker stop``) and SIGHUP at stages
TERMINATE_STAGES = [
    ("analyze", "writing results", 0.3, signal.SIGTERM, "writing"),
    ("analyze", "building the isosurface", 0.05, signal.SIGHUP, "sighup-mesh"),
    ("compare", "writing results", 0.2, signal.SIGTERM, "writing"),
]
INTERRUPTS = [
    *(
        pytest.param(
            command, after, None, (), when, signal.SIGINT, id=f"{command}-interrupt-{stage}"
        )
        for command, when, after, stage in STAGES
    ),
    # Ctrl-C while a numba kernel runs, its threads busy
    pytest.param(
        "analyze",
        120,
        "combine_channels",
        (),
        None,
        signal.SIGINT,
        id="analyze-interrupt-in-combine-channels-kernel",
    ),
    pytest.param(
        "analyze",
        120,
        "first_crossing",
        (),
        None,
        signal.SIGINT,
        id="analyze-interrupt-in-first-crossing-kernel",
    ),
    pytest.param(
        "analyze",
        120,
        "bin_lateral",
        ("--iso-bin", "2"),
        None,
        signal.SIGINT,
        id="analyze-interrupt-in-bin-kernel",
    ),
    *(
        pytest.param(command, after, None, (), when, signum, id=f"{command}-terminate-{stage}")
        for command, when, after, signum, stage in TERMINATE_STAGES
    ),
    pytest.param(
        "analyze",
        120,
        "first_crossing",
        (),
        None,
        signal.SIGTERM,
        id="analyze-terminate-in-first-crossing-kernel",
    ),
    # mpm3d batch, one run after the other: SIGTERM while a run is written
    pytest.param("batch", 0.05, None, (), WRITING, signal.SIGTERM, id="batch-terminate-writing"),
    # the scratch of runs killed outright (SIGKILL), removed by the next run
    *(
        pytest.param(command, None, None, (), "stale", None, id=f"{command}-stale-killed-run")
        for command in ("analyze", "compare", "batch")
    ),
]


@pytest.mark.parametrize(("command", "after", "kernel", "extra", "when", "signum"), INTERRUPTS)
def test_interrupt(command, after, kernel, extra, when, signum, mpm_pair, mpm_small, tmp_path):
    before, later = mpm_pair["before"][0], mpm_pair["after"][0]
    out = tmp_path / "out"
    if when == "stale":
        _killed_then_run_again(command, mpm_small[0], tmp_path)
        return
    if kernel is not None:  # the largest test stack: the kernels run longest
        inputs = [later]
        name = kernel if signum == signal.SIGINT else f"{kernel}:{signal.Signals(signum).name}"
        argv = ["-c", IN_KERNEL, name, "analyze", later, "--out", out, "--no-figures", *extra]
    elif command == "analyze":
        inputs = [before]
        argv = ["-m", "mpm3d", "analyze", before, "--out", out]
    elif command == "batch":  # the signal while its first run is written: watch that run
        inputs = [before, later]
        argv = ["-m", "mpm3d", "batch", before, later, "--workers", "1", "--out", tmp_path / "b"]
        out = tmp_path / "b" / "runs" / "before"
    else:
        inputs = [before, later]
        argv = ["-m", "mpm3d", "compare", before, later, "--out", out, "--no-surface"]
        argv += ["--icp", "off"]
    status, err = interrupt(argv, after=after, when=when, out=out, inputs=inputs, signum=signum)
    if kernel is not None:
        assert status == 128 + signum and not out.exists(), err
        assert f"[kernel {kernel} interrupted: " in err, err  # Ctrl-C ended the kernel calls
    elif status == 0:
        assert (out / ("metrics.json" if command == "analyze" else "compare.json")).is_file()
    if command == "batch":
        assert status == 143 and not out.exists(), err
        assert scratch_left(tmp_path / "b") == []


def _killed_then_run_again(command: str, stack: Path, tmp_path: Path) -> None:
    """A run killed (SIGKILL) while it wrote; the next run removes what it left."""
    out = tmp_path / "out"
    if command == "analyze":
        argv = ["analyze", str(stack), "--out", str(out)]
        assert killed(["-m", "mpm3d", *argv], out=out)  # a real run, killed mid-way
    elif command == "compare":
        argv = ["compare", str(stack), str(stack), "--out", str(out), "--no-surface"]
        stale_scratch(out)
    else:  # a batch killed while it wrote its first run, and one killed writing metrics.csv
        argv = ["batch", str(stack), "--workers", "1", "--out", str(out)]  # figures: seconds
        assert killed(["-m", "mpm3d", *argv], out=out / "runs" / "small")
        stale_scratch(out / "metrics.csv", "file")
    assert run(["-q", *argv]) == 0
    for folder in (tmp_path, out, out / "runs"):
        if folder.is_dir():
            assert scratch_left(folder) == [], folder
    assert not (out / ".batch.lock").exists()


def test_every_command_has_terminate_and_stale_cases():
    ids = [p.id for p in INTERRUPTS]
    for command in (*COMMANDS, "batch"):
        for family in ("terminate", "stale"):
            assert any(i.startswith(f"{command}-{family}-") for i in ids), (command, family)


class _ConvertedByMatplotlib:
    """An array whose conversion Ctrl-C interrupts, inside matplotlib's compiled code."""

    def __array__(self, *args, **kwargs):
        os.kill(os.getpid(), signal.SIGINT)  # the KeyboardInterrupt is raised here ...
        return np.zeros((1, 2))


def _lose_a_ctrl_c(how: str) -> None:
    """Ctrl-C that lands where a library loses its KeyboardInterrupt."""
    if how == "swallowed":
        # Python code that catches everything and goes on; CPython itself dropped one this way,
        # for the ValueError of int("normal") in matplotlib's font matching, during a real run
        try:
            os.kill(os.getpid(), signal.SIGINT)
        except BaseException:
            pass
    else:  # ... and pybind11 turns it into a TypeError of its own
        from matplotlib import _path

        _path.affine_transform(_ConvertedByMatplotlib(), np.eye(3))


@pytest.mark.parametrize(
    ("how", "stage"),
    [
        ("swallowed", "writing"),
        ("replaced", "writing"),
        ("swallowed", "after-writing"),
    ],
)
def test_interrupt_lost_in_a_library(how, stage, mpm_small, tmp_path, monkeypatch, capsys, request):
    """A KeyboardInterrupt that never arrives still ends the command with 130: no output while
    it is written, and a line that says so once it is in place (the Ctrl-C is remembered)."""
    import mpm3d.cli
    from mpm3d import figures

    # Python's own handler, as in a terminal (a shell's background job starts with SIGINT
    # ignored, and then the toolkit leaves it so)
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    request.addfinalizer(lambda: signal.signal(signal.SIGINT, previous))
    out = tmp_path / "out"
    if stage == "writing":
        real = figures.plot_spectrum  # while the figures are written, before the rename

        def patched(*args, **kwargs):
            _lose_a_ctrl_c(how)
            return real(*args, **kwargs)

        monkeypatch.setattr(figures, "plot_spectrum", patched)
    else:
        real = mpm3d.cli._summary  # the line printed once the result is in place

        def patched(*args, **kwargs):
            _lose_a_ctrl_c(how)
            return real(*args, **kwargs)

        monkeypatch.setattr(mpm3d.cli, "_summary", patched)
    status = run(["analyze", str(mpm_small[0]), "--out", str(out), "-q"])
    err = capsys.readouterr().err
    assert status == 130, err
    if stage == "writing":
        assert err == "mpm3d analyze: interrupted; no output written\n"
        assert not out.exists()
    else:
        assert err == f"mpm3d analyze: interrupted after the results were written to {out}\n"
        assert (out / "metrics.json").is_file()
    assert [p.name for p in tmp_path.iterdir() if p.name != "out"] == []  # no scratch left
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_compare_reads_both_headers_before_the_first_analysis(
    mpm_small, tmp_path, capsys, monkeypatch
):
    """A truncated after stack, or a channel it lacks, was found only once the before stack
    had been analysed."""
    import mpm3d.compare

    analysed = []
    monkeypatch.setattr(mpm3d.compare, "analyze_stack", lambda *a, **k: analysed.append(a))
    stack = mpm_small[0]
    after = cut(stack, tmp_path, 0.5, "after.tif")
    argv = ["-q", "compare", str(stack), str(after), "--out", str(tmp_path / "out")]
    assert run(argv) == 2
    assert "after stack" in capsys.readouterr().err and analysed == []
    one = imagej(tmp_path, "one.tif", stack_data(stack)[:, :1])  # one channel, named "0"
    argv = ["-q", "compare", str(stack), str(one), "--channel", "1", "--out", str(tmp_path / "o")]
    assert run(argv) == 2
    assert "after stack" in capsys.readouterr().err and analysed == []


# --------------------------------------------------------------------------- names


# Names that are not UTF-8 (Windows-origin and shared drives) are read and written; each case
# is a real process given its names as bytes (VTK raised on them, and matplotlib on the
# figure titles naming the stack): exit 0, the metrics of plainly named stacks, and every
# text file valid UTF-8 (names shown as \xNN).

#: metrics that must not depend on the names
MEASURED = ("n_folds", "fold_height_um", "fold_wavelength_um", "surface_coverage")


@pytest.fixture(scope="module")
def latin1_stacks(mpm_small, tmp_path_factory):
    """``(folder, before, after, reference metrics of before)``: the small stack, and a copy
    of it with its rows flipped, named in Latin-1 in a folder so named."""
    plain = tmp_path_factory.mktemp("plain")
    folder = tmp_path_factory.mktemp(latin1("Messdatén"))
    before, after = folder / latin1("stäck.tif"), folder / latin1("après.tif")
    before.write_bytes(mpm_small[0].read_bytes())
    with tifffile.TiffFile(mpm_small[0]) as tif:
        data, metadata = tif.asarray(), tif.imagej_metadata
    tifffile.imwrite(after, data[..., ::-1, :], imagej=True, metadata=metadata)
    assert run(["-q", "analyze", str(mpm_small[0]), "--no-figures", "--out",
                str(plain / "ref")]) == 0  # fmt: skip
    return folder, before, after, strict_json(plain / "ref" / "metrics.json")


def _names_analyze(folder, before, after, reference, tmp):
    out = tmp / latin1("résultats")
    assert_ran(["-m", "mpm3d", "analyze", before, "--out", out], out)
    metrics = strict_json(out / "metrics.json")
    assert {k: metrics[k] for k in MEASURED} == {k: reference[k] for k in MEASURED}
    assert metrics["input"] == shown(before.name)
    assert {"surface.vtp", "surface.ply", "figures"} <= {p.name for p in out.iterdir()}
    assert (out / "figures" / "surface3d.png").stat().st_size > 0


def _names_compare(folder, before, after, reference, tmp):
    out = tmp / latin1("comparé")
    assert_ran(["-m", "mpm3d", "compare", before, after, "--no-surface", "--out", out], out)
    metrics = strict_json(out / "before" / "metrics.json")
    assert {k: metrics[k] for k in MEASURED} == {k: reference[k] for k in MEASURED}
    assert (out / "figures" / "compare_heightmaps.png").stat().st_size > 0


def _names_batch(folder, before, after, reference, tmp):
    out = tmp / latin1("lot_é")
    argv = ["-m", "mpm3d", "batch", before, after, "--no-figures", "--no-surface",
            "--workers", "1", "--out", out]  # fmt: skip
    assert_ran(argv, out)
    table = (out / "metrics.csv").read_text(encoding="utf-8")
    assert "\nst\\xe4ck," in table and "\napr\\xe8s," in table
    assert (out / "runs" / latin1("stäck") / "metrics.json").is_file()
    err = assert_ran(argv, out)  # the runs' markers name them readably, and exactly
    assert "2 complete already, nothing to run" in err, err


def _names_damaged_stack(folder, before, after, reference, tmp):
    stack = write(tmp, latin1("abîmé.tif"), "not a stack\n")
    assert_refused_process(["-m", "mpm3d", "analyze", stack, "--out", tmp / "out"],
                           fragments=["mpm3d analyze: error:", shown(stack)])  # fmt: skip
    assert not (tmp / "out").exists()


NAME_CASES = {
    "analyze-filename-damaged-stack": _names_damaged_stack,
    "analyze-filename-stack-and-out": _names_analyze,
    "compare-filename-stacks-and-out": _names_compare,
    "batch-filename-stacks-and-out": _names_batch,
}


@pytest.mark.xdist_group("mpm3d_latin1_names")  # its names' folder made once, on one worker
class TestNamesNotUtf8:
    """The bad-input matrix's ``filename`` family: names that are not UTF-8 are read and
    written (``test_bad_input[COMMAND-filename-CASE]``, counted with the refusals)."""

    @pytest.mark.parametrize("case", list(NAME_CASES), ids=list(NAME_CASES))
    def test_bad_input(self, latin1_stacks, tmp_path, case):
        folder = latin1_stacks[0]
        tmp = tmp_path / latin1("dossier_é")
        tmp.mkdir()
        before = snapshot(folder)
        NAME_CASES[case](*latin1_stacks, tmp)
        assert snapshot(folder) == before  # inputs untouched
        assert scratch_left(tmp) == []
