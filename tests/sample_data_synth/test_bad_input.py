"""Bad options for every sample_data_synth command: exit 2, one line, nothing written.

See tests/badinput.py for the contract and the families.
"""

from __future__ import annotations

import signal

import pytest

import tissue_core.resources as resources
from sample_data_synth.cli import main
from tests.badinput import (
    assert_refused,
    interrupt,
    parse_case_id,
    stale_scratch,
    write,
)
from tests.filenames import assert_ran, assert_refused_process, latin1, shown

PROG = "sample_data_synth"

CASES = [
    # ---- video
    ("video-option-unknown-case", ["video", "--case", "bend"], ["bend"]),
    ("video-option-size-small", ["video", "--size", "10"], ["--size"]),
    ("video-option-size-text", ["video", "--size", "big"], ["--size"]),
    ("video-option-frames-one", ["video", "--frames", "1"], ["--frames"]),
    ("video-option-formats", ["video", "--formats", "avi,gif"], ["--formats"]),
    ("video-option-formats-empty", ["video", "--formats", ","], ["--formats"]),
    ("video-option-read-noise-negative", ["video", "--read-noise=-1"], ["--read-noise"]),
    ("video-option-read-noise-nan", ["video", "--read-noise", "nan"], ["--read-noise"]),
    ("video-option-shot-gain-inf", ["video", "--shot-gain", "inf"], ["--shot-gain"]),
    ("video-option-seed-negative", ["video", "--seed=-1"], ["--seed"]),
    # ---- stack
    ("stack-option-unknown-case", ["stack", "--case", "during"], ["during"]),
    ("stack-option-spacing-two", ["stack", "--spacing", "4,5"], ["--spacing"]),
    ("stack-option-spacing-zero", ["stack", "--spacing", "0,5,5"], ["--spacing"]),
    ("stack-option-spacing-nan", ["stack", "--spacing", "nan,5,5"], ["--spacing"]),
    ("stack-option-format", ["stack", "--format", "zarr"], ["--format"]),
    ("stack-option-size-small", ["stack", "--size", "8"], ["--size"]),
    ("stack-option-slices-one", ["stack", "--slices", "1"], ["--slices"]),
    ("stack-option-seed-negative", ["stack", "--seed=-3"], ["--seed"]),
    # ---- stereo
    ("stereo-option-unknown-case", ["stereo", "--case", "sphere"], ["sphere"]),
    ("stereo-option-board", ["stereo", "--board", "chess:9x6:10"], ["chess"]),
    ("stereo-option-board-squares", ["stereo", "--board", "checkerboard:1x6:10"], []),
    ("stereo-option-views-zero", ["stereo", "--views", "0"], ["--views"]),
    ("stereo-option-frames-one", ["stereo", "--frames", "1"], ["--frames"]),
    ("stereo-option-size", ["stereo", "--size", "1024"], ["--size"]),
    ("stereo-option-size-small", ["stereo", "--size", "32x32"], ["--size"]),
    ("stereo-option-noise-negative", ["stereo", "--noise=-2"], ["--noise"]),
    # ---- study
    ("study-option-texture", ["study", "--texture", "wood"], ["--texture"]),
    ("study-option-per-group-zero", ["study", "--per-group", "0"], ["--per-group"]),
    ("study-option-frames-two", ["study", "--frames", "2"], ["--frames"]),
    ("study-option-heterogeneity", ["study", "--heterogeneity", "1"], ["--heterogeneity"]),
    ("study-option-heterogeneity-nan", ["study", "--heterogeneity", "nan"], ["--heterogeneity"]),
    ("study-option-size-small", ["study", "--size", "32"], ["--size"]),
    # ---- sizes beyond the memory or the disk: refused before anything is made
    (
        "video-allocation-size-100000",
        ["video", "--size", "100000"],
        ["--size 100000", "100000x100000 px", "885 GiB of memory", "available"],
    ),
    (
        "video-allocation-frames",
        ["video", "--frames", "100000000"],
        ["--frames 100000000", "TiB of memory"],
    ),
    (
        "video-allocation-disk",
        ["video", "--size", "256", "--formats", "tif"],
        ["--size 256", "writes 1.94 MiB", "1 MiB free"],
    ),
    (
        "stack-allocation-size-100000",
        ["stack", "--size", "100000"],
        ["--size 100000", "26 or more slices", "TiB of memory"],
    ),
    (
        "stack-allocation-slices",
        ["stack", "--size", "64", "--slices", "100000000"],
        ["--slices 100000000", "of memory"],
    ),
    (
        "stereo-allocation-size-100000x100000",
        ["stereo", "--size", "100000x100000"],
        ["--size 100000x100000", "TiB of memory"],
    ),
    (
        "stereo-allocation-views",
        ["stereo", "--views", "100000000"],
        ["--views 100000000", "TiB of memory"],
    ),
    (
        "stereo-allocation-board-corners",
        ["stereo", "--size", "256x192", "--board", "checkerboard:100000x100000:10"],
        ["--board checkerboard:100000x100000:10", "at most 64x48", "4 px apart"],
    ),
    (
        "study-allocation-size-100000",
        ["study", "--size", "100000"],
        ["--size 100000", "GiB of memory"],
    ),
    (
        "study-allocation-per-group",
        ["study", "--per-group", "1000000000"],
        ["--per-group 1000000000", "2000000000 videos", "TiB", "free"],
    ),
]

#: the disk space free, bytes, in the cases that write more than there is
SMALL_DISK = {"video-allocation-disk": 2**20}

OUTPUT_CASES = [
    (f"{command}-output-{name}", [command, *extra], fragments)
    for command in ("video", "stack", "stereo", "study")
    for name, extra, fragments in (
        ("users-folder", ["@mine"], ["thesis", "not a result"]),
        ("users-folder-overwrite", ["@mine", "--overwrite"], ["thesis", "not a result"]),
        ("working-directory", ["@cwd", "--overwrite"], ["working directory"]),
        ("missing-parent", ["@nowhere"], ["does not exist"]),
    )
]

ALL = CASES + OUTPUT_CASES


@pytest.mark.parametrize(("case", "argv", "fragments"), ALL, ids=[c[0] for c in ALL])
def test_bad_input(tmp_path, capsys, monkeypatch, case, argv, fragments):
    mine = tmp_path / "thesis"
    mine.mkdir()
    (mine / "chapter.tex").write_text("years of work")
    here = tmp_path / "here"
    here.mkdir()
    (here / "data.csv").write_text("x,y\n")
    monkeypatch.chdir(here)
    if case in SMALL_DISK:
        monkeypatch.setattr(resources, "free_disk", lambda path: SMALL_DISK[case])
    out = tmp_path / "out"
    where = {"@mine": mine, "@cwd": ".", "@nowhere": tmp_path / "no" / "out"}
    target = next((where[a] for a in argv if a in where), out)
    args = [a for a in argv if a not in where]
    full = [args[0], "-q", *args[1:], "--out", str(target)]
    assert_refused(main, full, capsys, prog=PROG, fragments=fragments, inputs=[mine, here],
                   out=out)  # fmt: skip
    assert sorted(p.name for p in tmp_path.iterdir()) == ["here", "thesis"]


def test_bad_input_cases_name_their_command_and_family():
    for case, *_ in ALL:
        command, _family, name = parse_case_id(case)
        assert command in ("video", "stack", "stereo", "study") and name, case
    assert len({c[0] for c in ALL}) == len(ALL)


#: small but real runs of each command (seconds)
SMALL = {
    "video": ["--size", "200", "--frames", "6"],
    "stack": ["--case", "before", "--size", "96"],
    "stereo": ["--case", "dome", "--frames", "2", "--size", "320x240"],
    "study": ["--size", "96", "--frames", "6", "--per-group", "1"],
}
#: runs long enough for a signal to land while they render
LONGER = {
    "video": ["--size", "300", "--frames", "20"],
    "stack": ["--case", "before", "--size", "256"],
    "stereo": ["--case", "dome", "--frames", "3", "--size", "320x240"],
    "study": ["--size", "128", "--frames", "20"],
}

INTERRUPTS = [
    ("study", None, 0.3, signal.SIGINT, "study-interrupt-imports"),
    ("study", "rendering", 0.2, signal.SIGINT, "study-interrupt-rendering"),
    ("study", "rendering", 1.0, signal.SIGINT, "study-interrupt-later"),
    *(
        (command, "rendering", 0.2, signal.SIGTERM, f"{command}-terminate-rendering")
        for command in ("video", "stack", "stereo", "study")
    ),
    ("video", "rendering", 0.2, signal.SIGHUP, "video-terminate-sighup-rendering"),
    *(
        (command, "stale", None, None, f"{command}-stale-killed-run")
        for command in ("video", "stack", "stereo", "study")
    ),
]


@pytest.mark.parametrize(
    ("command", "when", "after", "signum"),
    [c[:4] for c in INTERRUPTS],
    ids=[c[4] for c in INTERRUPTS],
)
def test_interrupt(tmp_path, command, when, after, signum):
    out = tmp_path / command
    if when == "stale":  # a run killed (SIGKILL) while it wrote: the next one removes its scratch
        stale_scratch(out)
        assert main(["-q", command, *SMALL[command], "--out", str(out)]) == 0
        assert [p.name for p in tmp_path.iterdir()] == [command]
        return
    status, _ = interrupt(
        ["-m", "sample_data_synth", command, *LONGER[command], "--out", out],
        after=after, when=when, out=out, signum=signum,
    )  # fmt: skip
    assert status == 128 + signum
    assert [p.name for p in tmp_path.iterdir()] == []


# ---- names that are not UTF-8 (Windows-origin and shared drives) ---------------------------
# Written, in a real process given the name as bytes (OpenCV crashed the process on a video so
# named): exit 0, the same files as under a plain name, every text file valid UTF-8.

NAME_CASES = [
    ("video-filename-out", ["video", "--size", "64", "--frames", "3", "--formats", "avi,tif,mp4"]),
    ("stack-filename-out", ["stack", "--size", "48", "--case", "before"]),
    (
        "stereo-filename-out",
        ["stereo", "--case", "calibration", "--size", "240x180", "--views", "2"],
    ),
    ("study-filename-out", ["study", "--size", "64", "--frames", "3", "--per-group", "1"]),
    # a folder of the user's so named is refused, and named readably
    ("video-filename-users-folder", ["video", "--size", "64", "--frames", "3"]),
]


class TestNamesNotUtf8:
    """The bad-input matrix's ``filename`` family: outputs named so, in folders so named, are
    written (``test_bad_input[COMMAND-filename-out]``, counted with the refusals)."""

    @pytest.mark.parametrize(("case", "argv"), NAME_CASES, ids=[c[0] for c in NAME_CASES])
    def test_bad_input(self, tmp_path, case, argv):
        from tissue_core.batch import differences

        assert parse_case_id(case)[:2] == (argv[0], "filename")
        out = tmp_path / latin1("Messdatén") / latin1("donnéés")
        out.parent.mkdir()
        if case.endswith("-users-folder"):
            thesis = write(out, latin1("thèse.tex"), "years of work")
            argv = ["-m", "sample_data_synth", *argv, "--out", out, "--overwrite"]
            assert_refused_process(argv, fragments=[shown(out), "not a result"])
            assert [p.name for p in out.iterdir()] == [thesis.name]
            assert thesis.read_text() == "years of work"
            return
        assert_ran(["-m", "sample_data_synth", *argv, "--out", out], out)
        plain = tmp_path / "plain"
        assert main([*argv, "-q", "--out", str(plain)]) == 0
        assert differences(out, plain) == []
        assert sorted(p.name for p in out.parent.iterdir()) == [out.name]


def test_every_command_has_terminate_and_stale_cases():
    ids = [c[4] for c in INTERRUPTS]
    for command in ("video", "stack", "stereo", "study"):
        for family in ("terminate", "stale"):
            assert any(i.startswith(f"{command}-{family}-") for i in ids), (command, family)
