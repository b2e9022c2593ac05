"""Every package's command line follows the same conventions (tissue_core.cli.CommandLine)."""

import importlib

import pytest

from tissue_core.version import __version__

OUT = ["--out", "/nonexistent/out"]
#: each command with the least it needs to parse
PACKAGES = {
    "strain2d": {
        "track": ["v.avi", *OUT],
        "analyze": ["v.avi", *OUT],
        "study": OUT,
        "benchmark": OUT,
    },
    "surface_strain": {"compute": ["points3d.csv", *OUT]},
    "stereo": {
        "calibrate": ["--left", "l", "--right", "r", "--board", "b", *OUT],
        "import-calib": ["calib.yml", *OUT],
        "match": ["l.png", "r.png", "--points", "p.csv", *OUT],
        "reconstruct": ["--calib", "c.json", "--left", "l.avi", "--right", "r.avi", *OUT],
    },
    "mpm3d": {"analyze": ["s.tif", *OUT], "compare": ["a.tif", "b.tif", *OUT]},
    "sample_data_synth": {
        "video": OUT,
        "stack": OUT,
        "stereo": OUT,
        "study": OUT,
        "list": [],
    },
}


def parser_of(package):
    return importlib.import_module(f"{package}.cli")._build_parser()


@pytest.mark.parametrize("package", PACKAGES)
def test_version_before_or_after_the_command(package, capsys):
    for argv in (["--version"], [next(iter(PACKAGES[package])), "--version"]):
        with pytest.raises(SystemExit) as exit_:
            parser_of(package).parse_args(argv)
        assert exit_.value.code == 0
        assert capsys.readouterr().out == f"{package} {__version__}\n"


@pytest.mark.parametrize("package", PACKAGES)
def test_quiet_and_verbose_before_or_after_the_command(package):
    parser = parser_of(package)
    for command, rest in PACKAGES[package].items():
        for argv, quiet, verbose in (
            ([command, *rest], False, False),
            (["-q", command, *rest], True, False),
            ([command, "-q", *rest], True, False),
            (["--verbose", command, *rest], False, True),
            ([command, *rest, "-v"], False, True),
        ):
            args = parser.parse_args(argv)
            assert (args.command, args.quiet, args.verbose) == (command, quiet, verbose), argv


@pytest.mark.parametrize("package", PACKAGES)
@pytest.mark.parametrize("argv", [["-q", "-v"], ["-v", "CMD", "-q"], ["CMD", "--quiet", "-v"]])
def test_quiet_with_verbose_is_refused(package, argv, capsys):
    command, rest = list(PACKAGES[package].items())[-1]
    argv = [command if a == "CMD" else a for a in argv]
    if command not in argv:
        argv.append(command)
    with pytest.raises(SystemExit) as exit_:  # a usage error, as argparse's own
        importlib.import_module(f"{package}.cli").main([*argv, *rest])
    err = capsys.readouterr().err
    assert exit_.value.code == 2
    assert err.strip().endswith("-q/--quiet and -v/--verbose cannot be used together"), err
    assert err.count("\n") == 1
