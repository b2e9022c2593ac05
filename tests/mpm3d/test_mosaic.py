"""Microscope mosaics: tiles at stage positions read as one stack (``mpm3d.mosaic``)."""

import csv
import json
import warnings

import numpy as np
import pytest
import tifffile

from mpm3d.analyze import analyze_stack
from mpm3d.errors import InputError, MosaicGapWarning, SourceError
from mpm3d.mosaic import open_mosaic
from sample_data_synth import make_stack_case, write_stack
from sample_data_synth.stacks import write_stack_tiles
from tests.mpm3d.helpers import cli

#: metrics that name the input, not the surface
_ABOUT_INPUT = {"input", "input_path", "inputs", "parameters", "command", "warnings"}


@pytest.fixture(scope="module")
def mosaic(tmp_path_factory):
    """A stack, its 3 x 3 mosaic (overlapping tiles, stage errors) and the tile list."""
    folder = tmp_path_factory.mktemp("mosaic")
    case = make_stack_case("after", size=(150, 190), spacing=(4.0, 5.0, 5.0), rng=4)
    whole = folder / "whole.tif"
    write_stack(whole, case)
    listing = write_stack_tiles(folder, case, tiles=(3, 3), overlap=0.15, rng=7)
    return whole, listing, case


def _write(path, rows):
    with open(path, "w", newline="") as f:
        csv.writer(f).writerows([["file", "x_um", "y_um"], *rows])
    return path


def test_tiles_read_as_the_stack_they_were_cut_from(mosaic):
    """Stage positions off by up to 0.2 px round to the true offsets: every pixel, whole or
    strided, is the stack's."""
    _, listing, case = mosaic
    with open(listing, newline="") as f:
        positions = list(csv.DictReader(f))
    assert any(float(p["x_um"]) % 5.0 not in (0.0,) for p in positions)  # not on the grid
    stack = open_mosaic(listing)
    with stack.data as data:
        assert data.shape == case.stack.shape
        assert data.covered_fraction == 1.0
        assert 0 < max(p.rounding_px for p in data.placements) < 0.5
        assert np.array_equal(data[:], case.stack)
        assert np.array_equal(data[::7, 1, 3:140:5, ::3], case.stack[::7, 1, 3:140:5, ::3])
        assert np.array_equal(data[-1, :, 60], case.stack[-1, :, 60])
    assert stack.spacing == (4.0, 5.0, 5.0)
    assert stack.channel_names == ("collagen", "urothelium")


def test_mosaic_metrics_equal_the_stitched_stacks(mosaic):
    """In memory and in bands of rows, the mosaic's analysis is the whole stack's, every
    metric and the height map bit for bit; the tiles and their placement are recorded."""
    whole, listing, _ = mosaic
    reference = analyze_stack(whole)
    for kwargs in ({}, {"tile_rows": 23}):
        run = analyze_stack(listing, **kwargs)
        assert run.params["memory"]["path"] == ("tiled" if kwargs else "in-memory")
        assert np.array_equal(run.heightmap.depth_um, reference.heightmap.depth_um)
        for key, value in reference.metrics.items():
            if key not in _ABOUT_INPUT:
                assert run.metrics[key] == value, key
        assert run.surface.n_cells == reference.surface.n_cells
        record = run.params["mosaic"]
        assert record["tiles"] == 9 and record["covered_fraction"] == 1.0
        assert len(run.metrics["inputs"]) == 10  # the list and its nine tiles


def test_overlaps_are_read_from_the_nearest_tile_centre(tmp_path):
    """Two tiles overlapping by 20 columns, of different values: the seam lies halfway
    between their centres, whatever the order they are listed in."""
    base = make_stack_case("before", size=(40, 60), spacing=(4.0, 1.0, 1.0), rng=1)
    for value, name in ((100, "a.tif"), (200, "b.tif")):
        tile = base.stack.copy()
        tile[:] = value
        write_stack(tmp_path / name, _replace_stack(base, tile))
    # a at columns 0..59, b at 40..99: centres 29.5 and 69.5, seam at 49.5
    for rows in ([["a.tif", 0, 0], ["b.tif", 40, 0]], [["b.tif", 40, 0], ["a.tif", 0, 0]]):
        stack = open_mosaic(_write(tmp_path / "m.csv", rows))
        with stack.data as data:
            row = data[0, 0, 5]
        assert (row[:50] == 100).all() and (row[50:] == 200).all()


def _replace_stack(case, stack):
    import dataclasses

    return dataclasses.replace(case, stack=stack)


def test_a_gap_is_read_as_zero_and_said(tmp_path, mosaic):
    _, listing, _ = mosaic
    folder = listing.parent
    rows = [["tile_r0_c0.tif", 0, 0], ["tile_r0_c2.tif", 5 * 129, 0]]
    path = _write(folder / "gap.csv", rows)
    with pytest.warns(MosaicGapWarning, match="lies in no tile"):
        stack = open_mosaic(path)
    with stack.data as data:
        assert 0 < data.covered_fraction < 1
        assert (data[:, :, :, 80] == 0).all()  # between the two tiles


@pytest.mark.parametrize(
    ("rows", "message"),
    [
        ([["tile_r0_c0.tif", 0, 0], ["missing.tif", 10, 0]], r"line 3: stack file not found"),
        ([["tile_r0_c0.tif", 0, "one"]], r"line 2: x_um and y_um must be numbers"),
        ([["tile_r0_c0.tif", 0, 0], ["tile_r0_c0.tif", 10, 0]], r"line 3: .* listed twice"),
        ([["tile_r0_c0.tif", 0, 0], ["tile_r0_c1.tif", 1e6, 0]], r"cover only .* micrometres"),
        ([["tile_r0_c0.tif", 0, 0], ["other.tif", 10, 0]], r"line 3: .*slices"),
        ([], r"no tiles listed"),
    ],
)
def test_bad_tile_lists_are_refused_with_their_line(mosaic, rows, message):
    _, listing, _ = mosaic
    folder = listing.parent
    if not (folder / "other.tif").exists():
        write_stack(folder / "other.tif", make_stack_case("before", size=32, n_slices=60, rng=0))
    path = _write(folder / "bad.csv", rows)
    with pytest.raises((InputError, SourceError), match=message):
        open_mosaic(path)


def test_cli_stitches_and_analyzes_a_mosaic(mosaic, tmp_path, capsys):
    whole, listing, case = mosaic
    out = tmp_path / "stitched.tif"
    assert cli("stitch", listing, "--out", out, "-q") == 0
    assert np.array_equal(tifffile.imread(out), case.stack)
    from mpm3d.io import read_stack

    assert read_stack(out).spacing == (4.0, 5.0, 5.0)
    # never over a tile, nor over an earlier result without --overwrite
    tile = listing.parent / "tile_r1_c1.tif"
    before = tile.read_bytes()
    capsys.readouterr()
    assert cli("stitch", listing, "--out", tile, "--overwrite", "-q") == 2
    assert tile.read_bytes() == before
    assert "would replace the input" in capsys.readouterr().err
    assert cli("stitch", listing, "--out", out, "-q") == 2
    assert "--overwrite" in capsys.readouterr().err
    run = tmp_path / "run"
    assert cli("analyze", listing, "--out", run, "--tile-rows", "40", "-q") == 0
    metrics = json.loads((run / "metrics.json").read_text())
    assert metrics["parameters"]["mosaic"]["tiles"] == 9
    assert metrics["parameters"]["memory"]["path"] == "tiled"
    assert "<th>mosaic</th><td>9 tiles, 100.0 % of the extent covered" in (
        run / "report.html"
    ).read_text(encoding="utf-8")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        reference = analyze_stack(whole).metrics
    assert metrics["fold_wavelength_um"] == reference["fold_wavelength_um"]
    assert metrics["Sq_um"] == reference["Sq_um"]
