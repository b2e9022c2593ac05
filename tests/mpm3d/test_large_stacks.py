"""Stacks larger than memory: read in bands of rows, the same results as in memory.

Small stacks forced through many bands (``tile_rows``, a memory limit just
above the smallest that works) must give the in-memory path's height map,
mesh and metrics.json bit for bit: the bands overlap by what each step's
support needs (see :mod:`mpm3d.tiled`), and the whole-map steps are shared.
bench/bench_mpm3d_memory.py shows the peak memory on a stack 4x the limit.
"""

import json
import math
import signal
import warnings

import numpy as np
import pytest
import tifffile

from mpm3d.analyze import analyze_stack
from mpm3d.cli import main
from mpm3d.errors import InputError
from mpm3d.io import read_stack
from mpm3d.lazyio import open_stack_lazily
from mpm3d.tiled import format_bytes, parse_memory, plan_memory
from sample_data_synth import make_stack_case, write_stack
from tests.badinput import assert_refused, interrupt
from tests.mpm3d.helpers import cli

#: the part of metrics.json that records the path taken: the only part allowed to differ
PATH_RECORD = "memory"


def _comparable(metrics: dict) -> str:
    """metrics.json as text, without the record of the path (NaN compared as text)."""
    out = dict(metrics)
    out["parameters"] = {k: v for k, v in out["parameters"].items() if k != PATH_RECORD}
    return json.dumps(out, sort_keys=True, default=str)


@pytest.fixture(scope="module")
def in_memory(mpm_small):
    """The in-memory analyses the banded ones are compared with, by options."""
    path, _ = mpm_small
    cache = {}

    def get(**options):
        key = tuple(sorted(options.items()))
        if key not in cache:
            cache[key] = analyze_stack(path, **options)
            assert cache[key].metrics["parameters"]["memory"]["path"] == "in-memory"
        return cache[key]

    return get


@pytest.mark.parametrize(
    ("options", "tile_rows"),
    [
        pytest.param({}, 7, id="channels-combined-7-rows"),
        pytest.param({"channel": "1", "iso_bin": 2}, 5, id="one-channel-binned-5-rows"),
    ],
)
def test_bands_equal_in_memory(options, tile_rows, mpm_small, in_memory):
    path, _ = mpm_small
    whole = in_memory(**options)
    banded = analyze_stack(path, tile_rows=tile_rows, **options)
    record = banded.metrics["parameters"]["memory"]
    assert record["path"] == "tiled" and record["tile_rows"] == tile_rows
    ny = whole.heightmap.depth_um.shape[0]
    assert math.ceil(ny / tile_rows) >= 10  # many bands, the last one shorter
    for name in ("depth_um", "valid", "cnr", "peak"):
        assert np.array_equal(getattr(banded.heightmap, name), getattr(whole.heightmap, name))
    assert np.array_equal(banded.surface_intensity, whole.surface_intensity, equal_nan=True)
    from mpm3d.meshstream import DiskMesh

    # the banded path's mesh is never whole in memory: merged, smoothed and oriented a
    # band at a time through files; loaded whole here to compare
    assert isinstance(banded.surface, DiskMesh)
    a, b = whole.surface, banded.surface.polydata()
    assert a.n_points == b.n_points and a.n_cells == b.n_cells
    assert np.array_equal(a.points, b.points)
    assert np.array_equal(a.regular_faces, b.regular_faces)
    for name in ("Normals", "depth_um", "height_um"):
        assert np.array_equal(a.point_data[name], b.point_data[name]), name
    assert {k: a.field_data[k].tolist() for k in a.field_data} == {
        k: b.field_data[k].tolist() for k in b.field_data
    }
    assert _comparable(banded.metrics) == _comparable(whole.metrics)


def test_memory_limit_picks_the_path_and_the_smallest_limit_works(
    mpm_small, in_memory, tmp_path, capsys
):
    """A limit below the stack's working set reads it in bands; the limit an error names works."""
    path, _ = mpm_small
    out = tmp_path / "out"
    error = assert_refused(
        main,
        ["analyze", path, "--out", out, "--memory-limit", "100MB"],
        capsys,
        prog="mpm3d",
        fragments=["memory limit of 96MiB is too small", "--memory-limit"],
        inputs=[path],
        out=out,
    )
    smallest = error.split("--memory-limit ")[-1].split()[0]
    assert cli("analyze", path, "--out", out, "--memory-limit", smallest, "--no-figures") == 0
    metrics = json.loads((out / "metrics.json").read_text(encoding="utf-8"))
    record = metrics["parameters"]["memory"]
    assert record["path"] == "tiled"
    assert record["memory_limit_bytes"] == parse_memory(smallest)
    assert record["tile_rows"] >= 1 and record["estimated_peak_bytes"] <= parse_memory(smallest)
    whole = in_memory().metrics
    for key in ("fold_wavelength_um", "fold_height_um", "Sq_um", "n_surface_triangles"):
        assert metrics[key] == whole[key]
    assert metrics["quality"]["mesh"] == json.loads(json.dumps(whole["quality"]["mesh"]))
    assert "finding the surface" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("1.5GiB", 3 * 2**29),
        ("1.5 GB", 1_500_000_000),
        ("512MiB", 2**29),
        ("800mb", 800_000_000),
        ("2gib", 2**31),
    ],
)
def test_parse_memory(text, expected):
    assert parse_memory(text) == expected


@pytest.mark.parametrize("text", ["1.5", "GiB", "1.5 GX", "-1GiB", "0MB", "1,5GiB", ""])
def test_bad_memory_limit_is_one_line(text, mpm_small, tmp_path, capsys):
    path, _ = mpm_small
    out = tmp_path / "out"
    argv = ["analyze", path, "--out", out, "--memory-limit", text]
    assert_refused(main, argv, capsys, prog="mpm3d", fragments=["--memory-limit"], out=out)


def test_bad_tile_rows_is_one_line(mpm_small, tmp_path, capsys):
    path, _ = mpm_small
    out = tmp_path / "out"
    argv = ["analyze", path, "--out", out, "--tile-rows", "0"]
    assert_refused(main, argv, capsys, prog="mpm3d", fragments=["--tile-rows"], out=out)


def test_plan_memory():
    shape = (100, 2, 1000, 1000)  # 400 MB of uint16
    kw = {"combined": True, "channels_read": 2, "surface": True, "bin": 2}
    fits = plan_memory(shape, 2, limit=8 * 2**30, **kw)
    assert fits.path == "in-memory" and fits.tile_rows is None
    big = plan_memory(shape, 2, limit=fits.in_memory_bytes - 1, **kw)
    smaller = plan_memory(
        shape,
        2,
        limit=big.smallest_limit_bytes + (fits.in_memory_bytes - big.smallest_limit_bytes) // 8,
        **kw,
    )
    assert big.path == smaller.path == "tiled"
    assert 1 <= smaller.tile_rows < big.tile_rows <= 1000
    assert big.tiled_bytes <= big.limit_bytes and smaller.tiled_bytes <= smaller.limit_bytes
    forced = plan_memory(shape, 2, limit=8 * 2**30, lazy=True, **kw)
    assert forced.path == "tiled" and forced.tile_rows == 1000
    with pytest.raises(InputError, match=r"too small .* use --memory-limit (\S+) or more"):
        plan_memory(shape, 2, limit=big.smallest_limit_bytes - 1, **kw)
    assert parse_memory(format_bytes(big.smallest_limit_bytes)) >= big.smallest_limit_bytes


def test_a_wide_field_fits_a_gib_with_its_mesh_streamed():
    """240 x 4096 x 4096 px of 8 bits (3.75 GiB): within 1 GiB in bands, the height map's
    work maps on disk and the mesh through files, for the 20 million triangles its folds
    make (measured on the bench's stack); a mesh three times as dense (a ragged surface)
    is refused, naming the limit that holds its pieces and the other ways out."""
    from mpm3d import tiled

    shape = (240, 1, 4096, 4096)
    kw = {"combined": False, "channels_read": 1, "bin": 2}
    plan = plan_memory(shape, 1, limit=2**30, surface=False, **kw)
    assert plan.path == "tiled" and plan.tiled_bytes <= 2**30 and plan.tile_rows >= 16
    plan = plan_memory(shape, 1, limit=2**30, surface=True, **kw)
    assert plan.path == "tiled" and plan.tiled_bytes <= 2**30
    meshed = tiled.plan_surface(plan, 20_200_000, iso_bin=2)
    assert meshed.tiled_bytes <= 2**30 and meshed.mesh_piece_rows >= 8
    assert meshed.surface_tile_rows >= 8
    assert tiled.mesh_budget(meshed) >= 20_200_000
    with pytest.raises(InputError, match=r"too small for this surface's mesh") as refused:
        tiled.plan_surface(plan, 60_000_000, iso_bin=2)
    assert "--iso-bin" in str(refused.value) and "--no-surface" in str(refused.value)
    smallest = parse_memory(str(refused.value).split("--memory-limit ")[-1].split()[0])
    bigger = plan_memory(shape, 1, limit=smallest, surface=True, **kw)
    assert tiled.plan_surface(bigger, 60_000_000, iso_bin=2).tiled_bytes <= smallest


def _formats(folder, mpm_small):
    """Stacks as files of every layout the reader handles, beside read_stack's arrays."""
    case = make_stack_case("before", size=24, spacing=(4.0, 5.0, 5.0), rng=2)
    ome = folder / "ome.ome.tif"
    write_stack(ome, case, format="ome")
    plane = case.stack[:, 1]
    files = {"imagej": mpm_small[0], "ome": ome}
    for name, data, kw in (
        ("big-endian", plane, {"byteorder": ">"}),
        ("zlib", plane, {"compression": "zlib"}),
        ("float16", plane.astype(np.float16), {}),
        ("bool", plane > 1000, {}),
    ):
        files[name] = folder / f"{name}.tif"
        tifffile.imwrite(files[name], data, **kw)
    return files


def test_lazy_reader_equals_read_stack(mpm_small, tmp_path):
    keys = [
        (slice(None), 0, slice(5, 17), slice(None)),
        (slice(None, None, 3), slice(None), slice(None, None, 3), slice(None, None, 3)),
        (2,),
        (slice(None), slice(None), slice(-4, None), slice(3, 9)),
    ]
    for name, path in _formats(tmp_path, mpm_small).items():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # plain TIFFs carry no z step
            whole = read_stack(path, spacing=(4, 5, 5))
            lazy = open_stack_lazily(path, spacing=(4, 5, 5))
        with lazy.data as rows:
            assert lazy.shape == whole.shape and lazy.channel_names == whole.channel_names
            assert lazy.spacing == whole.spacing
            for key in keys:
                got, want = rows[key], np.asarray(whole.data[key])
                assert got.dtype == want.dtype and np.array_equal(got, want), (name, key)


@pytest.mark.parametrize(
    ("signum", "expected", "when"),
    [
        (signal.SIGINT, 130, "finding the surface: 0/"),
        (signal.SIGTERM, 143, "finding the surface: 0/"),
        (signal.SIGINT, 130, "building the isosurface: 0/"),
        (signal.SIGTERM, 143, "building the isosurface: 0/"),
    ],
)
def test_interrupt_while_banded_leaves_no_output(signum, expected, when, mpm_small, tmp_path,
                                                 monkeypatch):  # fmt: skip
    path, _ = mpm_small
    out = tmp_path / "out"
    work = tmp_path / "tmp"  # where the height map's and the mesh's work files go: left empty
    work.mkdir()
    monkeypatch.setenv("TMPDIR", str(work))
    argv = ["-m", "mpm3d", "analyze", path, "--out", out, "--tile-rows", "1", "--no-figures"]
    # while the bands are read, or the mesh is streamed: the work folder exists
    status, err = interrupt(argv, after=0.0, when=when, out=out, inputs=[path], signum=signum)
    assert status == expected and not out.exists(), err
    assert list(work.iterdir()) == []


def test_a_banded_run_leaves_no_work_files(mpm_small, tmp_path, monkeypatch):
    """The mesh's files (and the maps') go when the run is written."""
    path, _ = mpm_small
    work = tmp_path / "tmp"
    work.mkdir()
    monkeypatch.setenv("TMPDIR", str(work))
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", None)
    out = tmp_path / "out"
    assert cli("analyze", path, "--out", out, "--lazy", "-q") == 0
    assert (out / "surface.ply").is_file() and (out / "figures" / "surface3d.png").is_file()
    assert list(work.iterdir()) == []


def test_a_full_disk_while_the_mesh_is_written_is_one_clear_error(tmp_path, monkeypatch):
    import builtins
    import errno

    from mpm3d.meshstream import _Rows

    rows = _Rows(tmp_path / "rows.bin", np.int64, 3)
    rows.append(np.zeros((2, 3)))
    real_open = builtins.open

    def full(file, mode="r", *args, **kwargs):
        if "a" in mode or "+" in mode:
            raise OSError(errno.ENOSPC, "No space left on device")
        return real_open(file, mode, *args, **kwargs)

    monkeypatch.setattr(builtins, "open", full)
    with pytest.raises(InputError, match=r"disk filled up .* TMPDIR"):
        rows.append(np.zeros((1, 3)))
    with pytest.raises(InputError, match="disk filled up"):
        rows.put(0, np.zeros((1, 3)))
    monkeypatch.setattr(builtins, "open", real_open)
    assert len(rows) == 2 and np.array_equal(rows.read(0, 5), np.zeros((2, 3)))


@pytest.mark.parametrize(("name", "iso_bin"), [("before", 2), ("after", 2), ("after", 3)])
def test_mesh_estimate_from_the_height_map(name, iso_bin):
    """The triangles the bands are sized for, estimated from the height map's developed area
    before the isosurface is built, are within 15 % of the mesh's, flat or steeply folded."""
    from mpm3d.tiled import mesh_triangles

    case = make_stack_case(name, size=160, spacing=(4.0, 2.5, 2.5), rng=2)
    from mpm3d.io import Stack

    stack = Stack(case.stack, case.spacing, "user", case.channel_names, "synthetic", "ZCYX")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run = analyze_stack(stack, iso_bin=iso_bin)
    estimate = mesh_triangles(run.heightmap.depth_um, case.spacing, iso_bin)
    assert abs(estimate / run.surface.n_cells - 1) < 0.15


def test_a_mesh_too_large_for_the_limit_is_refused_with_the_limit_that_works(tmp_path, capsys):
    """Steep folds make a mesh that a band plan from the stack's size alone would not
    hold: the run stops after the height map, names the limit that works, and that
    limit works (estimated peak within it)."""
    case = make_stack_case("after", size=160, spacing=(4.0, 2.5, 2.5), rng=2)
    path = tmp_path / "after.tif"
    write_stack(path, case)
    out = tmp_path / "out"
    first = assert_refused(
        main,
        ["analyze", path, "--out", out, "--memory-limit", "100MB"],
        capsys,
        prog="mpm3d",
        fragments=["even one row at a time needs"],
        inputs=[path],
        out=out,
    )
    enough_for_bands = first.split("--memory-limit ")[-1].split()[0]
    error = assert_refused(
        main,
        ["analyze", path, "--out", out, "--memory-limit", enough_for_bands],
        capsys,
        prog="mpm3d",
        fragments=["too small for this surface's mesh", "--iso-bin", "--no-surface"],
        inputs=[path],
        out=out,
    )
    smallest = error.split("--memory-limit ")[-1].split()[0]
    assert parse_memory(smallest) > parse_memory(enough_for_bands)
    assert cli("analyze", path, "--out", out, "--memory-limit", smallest, "-q") == 0
    record = json.loads((out / "metrics.json").read_text(encoding="utf-8"))["parameters"]
    assert record["memory"]["path"] == "tiled"
    assert record["memory"]["estimated_peak_bytes"] <= parse_memory(smallest)
    assert record["memory"]["estimated_mesh_triangles"] > 0


def _contoured(mpm_small, bin: int):
    """The small stack, its isosurface's plan and volume (the analysis' options)."""
    from mpm3d.heightmap import height_map
    from mpm3d.io import select_channel
    from mpm3d.surface import iso_plan

    stack = read_stack(mpm_small[0])
    volume, _ = select_channel(stack)
    hm = height_map(volume, spacing=stack.spacing)
    plan = iso_plan(volume.shape, volume.dtype, spacing=stack.spacing, level=0.5, bin=bin,
                    depth_um=hm.depth_um, column_scale=(hm.background, hm.peak))  # fmt: skip
    return stack, volume, plan


def _merged_mesh(mpm_small):
    """The small stack's isosurface before smoothing (merged, its largest piece), its plan,
    and each point's row of pixels."""
    import pyvista as pv

    from mpm3d.surface import _canonical, column_work, contour_rows, largest_component

    stack, volume, plan = _contoured(mpm_small, 1)
    points, tris = _canonical(*contour_rows(column_work(volume, plan, 0), plan, 0))
    faces = np.column_stack([np.full(len(tris), 3), tris]).ravel()
    mesh = largest_component(pv.PolyData(points, faces))
    return mesh, plan, np.asarray(mesh.points)[:, 1] / stack.spacing[1]


def _piece(mesh, row: np.ndarray, a: int, b: int, halo: int):
    """The piece of ``mesh`` in rows ``a - halo .. b + halo`` (its points and triangles in
    the mesh's order), and of its points, those of rows ``a .. b`` and their indices in
    ``mesh``."""
    import pyvista as pv

    p, f = np.asarray(mesh.points), mesh.regular_faces
    kept = (row >= a - halo) & (row < b + halo)
    used = np.flatnonzero(kept)
    index = np.full(len(p), -1)
    index[used] = np.arange(len(used))
    inside = f[kept[f].all(axis=1)]
    part = pv.PolyData(p[used], np.column_stack([np.full(len(inside), 3), index[inside]]))
    core = (row[used] >= a) & (row[used] < b)
    return part, core, used[core]


@pytest.mark.parametrize(("rows", "iterations"), [((20, 40), 10), ((0, 30), 10), ((50, 96), 12)])
def test_a_piece_of_the_mesh_is_smoothed_as_the_whole_mesh_is(rows, iterations, mpm_small):
    """The premise of smoothing a mesh too large to hold whole a piece at a time: the
    smoothing's frame is the stack's, and ``iterations + 1`` binned rows of mesh around a
    band of rows are enough for its vertices to move exactly as in the whole mesh."""
    from mpm3d.surface import smooth_mesh

    mesh, plan, row = _merged_mesh(mpm_small)
    before = np.array(mesh.points)
    whole = np.asarray(smooth_mesh(mesh, plan, iterations=iterations).points)
    assert np.array_equal(np.asarray(mesh.points), before)  # the input mesh is left as it was
    for halo, same in ((iterations + 1, True), (2, False)):  # 2: the band's vertices move
        part, core, where = _piece(mesh, row, *rows, halo)
        got = np.asarray(smooth_mesh(part, plan, iterations=iterations).points)[core]
        assert len(got) > 100 and np.array_equal(got, whole[where]) == same, halo


def test_a_piece_of_the_smoothed_mesh_has_the_whole_meshs_normals(mpm_small):
    """VTK's point normals of a piece of the mesh with two rows of mesh around it are the
    whole mesh's (each vertex's from its own triangles, in the mesh's order)."""
    from mpm3d.surface import smooth_mesh

    merged, plan, _ = _merged_mesh(mpm_small)
    mesh = smooth_mesh(merged, plan).flip_faces()
    row = np.asarray(mesh.points)[:, 1] / plan.spacing[1]

    def normals(m) -> np.ndarray:
        m = m.compute_normals(cell_normals=False, split_vertices=False,
                              consistent_normals=False, auto_orient_normals=False)  # fmt: skip
        return np.asarray(m.point_data["Normals"])

    whole = normals(mesh)
    for (a, b), halo, same in (((20, 40), 2, True), ((0, 30), 2, True), ((20, 40), 1, False)):
        part, core, where = _piece(mesh, row, a, b, halo)
        assert np.array_equal(normals(part)[core], whole[where]) == same, (a, b, halo)


def test_the_mesh_points_of_bands_of_rows_follow_each_other_in_the_whole_meshs_order(mpm_small):
    """Points sorted by row first: the points of two bands contoured apart (sharing their
    boundary row, whose points the first band keeps) are the whole mesh's, in its order."""
    from mpm3d.surface import _canonical, column_work, contour_rows

    _, volume, plan = _contoured(mpm_small, 2)
    whole, _ = _canonical(*contour_rows(column_work(volume, plan, 0), plan, 0))
    cut = 20  # binned rows 0..20 and 20..: row 20 in both
    b = plan.bin
    first, _ = _canonical(*contour_rows(column_work(volume[:, : (cut + 1) * b], plan, 0), plan, 0))
    second, _ = _canonical(*contour_rows(column_work(volume[:, cut * b :], plan, cut), plan, cut))
    seam = first[:, 1].max()
    assert np.count_nonzero(second[:, 1] == seam) > 10  # the shared row's points, twice
    joined = np.concatenate([first, second[second[:, 1] > seam]])
    assert np.array_equal(joined, whole)


def test_a_mesh_larger_than_the_limit_holds_is_refused(mpm_small, tmp_path, capsys, monkeypatch):
    """The plan's mesh estimate comes from the height map; a ragged surface contours into
    more triangles. Both paths count them as they are contoured and stop with one line,
    before the mesh is merged and smoothed, where the limit does not hold them."""
    import mpm3d.tiled as tiled
    from mpm3d.surface import isosurface
    from mpm3d.tiled import check_triangles, mesh_budget

    shape = (100, 2, 1000, 1000)
    kw = {"combined": True, "channels_read": 2, "surface": True, "bin": 2}
    whole = plan_memory(shape, 2, limit=8 * 2**30, **kw)
    banded = tiled.plan_surface(plan_memory(shape, 2, limit=2**30, **kw), 10**6, iso_bin=2)
    budget = mesh_budget(whole)
    assert budget > 10**6 and budget * tiled.MESH_BYTES_PER_TRIANGLE <= whole.limit_bytes
    # banded, the mesh is streamed: as dense a mesh as lets a piece of it fit
    budget = mesh_budget(banded)
    piece = tiled.PIECE_BYTES_PER_TRIANGLE * (
        banded.mesh_piece_rows + 2 * tiled.SMOOTHING_HALO_ROWS
    )
    assert budget > 10**6 and budget * piece / 500 <= banded.limit_bytes
    assert mesh_budget(None) is None
    check_triangles(125, 100)  # within the margin
    with pytest.raises(InputError, match=r": 126 triangles so far, against 100 \("):
        check_triangles(126, 100, "so far")
    path, _ = mpm_small
    stack = read_stack(path)
    from mpm3d.io import select_channel

    volume, _ = select_channel(stack)
    with pytest.raises(InputError, match="larger than the memory limit holds"):
        isosurface(volume, spacing=stack.spacing, level=1000.0, max_triangles=100)
    # the command: a budget the mesh passes is refused with status 2, the banded path's
    # estimate made to pass (as a ragged surface's does)
    monkeypatch.setattr(tiled, "mesh_budget", lambda plan: 100)
    monkeypatch.setattr(tiled, "mesh_triangles", lambda *args: 1)
    for extra in ([], ["--lazy"]):
        out = tmp_path / f"run{len(extra)}"
        assert main(["analyze", str(path), "--out", str(out), "--memory-limit", "4GiB",
                     "--no-figures", *extra]) == 2  # fmt: skip
        err = capsys.readouterr().err
        last = err.strip().splitlines()[-1]
        assert last.startswith("mpm3d analyze: error:") and "larger than the memory limit" in last
        assert "Traceback" not in err
        assert not out.exists()


def test_a_streamed_mesh_is_written_as_the_in_memory_mesh_is(mpm_small, in_memory, tmp_path):
    """The banded path writes its mesh a chunk at a time: surface.ply byte for byte as
    VTK writes the in-memory mesh, surface.vtp read back with the same points,
    triangles, arrays and field data; its files go when it is closed."""
    import pyvista as pv

    path, _ = mpm_small
    whole = in_memory().surface
    streamed = analyze_stack(path, tile_rows=9).surface
    streamed.save_ply(tmp_path / "streamed.ply")
    whole.save(tmp_path / "whole.ply", binary=True)
    assert (tmp_path / "streamed.ply").read_bytes() == (tmp_path / "whole.ply").read_bytes()
    streamed.save_vtp(tmp_path / "streamed.vtp")
    back = pv.read(tmp_path / "streamed.vtp")
    assert np.array_equal(back.points, whole.points)
    assert np.array_equal(back.regular_faces, whole.regular_faces)
    for name in ("Normals", "depth_um", "height_um"):
        assert np.array_equal(back.point_data[name], whole.point_data[name]), name
    assert back.active_normals is not None
    assert str(back.field_data["height_datum"][0]) == str(whole.field_data["height_datum"][0])
    folder = streamed.folder.path
    assert folder.is_dir()
    streamed.close()
    assert not folder.exists()


class _Bands:
    """A volume in memory read as :class:`mpm3d.tiled.StackBands` reads a stack."""

    def __init__(self, volume: np.ndarray) -> None:
        self.volume, self.shape, self.dtype = volume, volume.shape, volume.dtype

    def rows(self, y0: int, y1: int) -> np.ndarray:
        return self.volume[:, y0:y1]


@pytest.mark.parametrize(
    ("sizes", "piece_rows"),
    [((5, 8), 3), ((6, 6), 4), ((7, 4), 1)],
    ids=["small-first", "tie", "large-first"],
)
def test_a_streamed_mesh_keeps_the_largest_piece_as_the_whole_mesh_does(sizes, piece_rows):
    """Two towers of tissue make two pieces of surface, in separate bands or sharing
    some: the streamed mesh keeps the larger (the one with the lowest point on a tie),
    smoothed and oriented as the whole mesh is."""
    from mpm3d.diskmaps import MapFolder
    from mpm3d.meshstream import stream_isosurface
    from mpm3d.surface import _contour_band, finish_isosurface, iso_plan

    nz, ny, nx = 12, 40, 30
    z, y, x = np.mgrid[:nz, :ny, :nx]
    volume = np.zeros((nz, ny, nx), np.float32)
    for (cy, cx), r in zip(((10, 9), (28, 20)), sizes, strict=True):
        volume[((y - cy) ** 2 + (x - cx) ** 2 <= r * r) & (z >= 3)] = 1.0
    plan = iso_plan(volume.shape, volume.dtype, spacing=(2.0, 1.0, 1.0), level=0.5, bin=1)
    bands = _Bands(volume)
    whole = finish_isosurface([_contour_band(bands, plan, 0, ny - 1)], plan, smooth_iterations=5)
    folder = MapFolder()
    streamed = stream_isosurface(bands, plan, tile_rows=3, folder=folder, piece_rows=piece_rows,
                                 smooth_iterations=5).polydata()  # fmt: skip
    folder.close()
    assert whole.n_cells > 100
    assert np.array_equal(streamed.points, whole.points)
    assert np.array_equal(streamed.regular_faces, whole.regular_faces)
    assert np.array_equal(streamed.point_data["Normals"], whole.point_data["Normals"])
    # the kept piece is the larger tower's (the first one's on a tie)
    centre = np.asarray(whole.points)[:, :2].mean(axis=0)
    kept = 0 if sizes[0] >= sizes[1] else 1
    assert np.hypot(*(centre - ((9, 10), (20, 28))[kept])) < 1.0


def test_writing_the_ply_leaves_the_mesh_as_it_was(mpm_small, tmp_path):
    """surface.ply holds the mesh's own triangles and normals: pyvista's PLY writer
    recomputes normals in place by default (cell normals added, windings made
    consistent by a traversal, which turned most triangles of a 20-million-triangle mesh
    with non-manifold edges around against surface.vtp's)."""
    import pyvista as pv

    from mpm3d.analyze import write_analysis

    path, _ = mpm_small
    analysis = analyze_stack(path)
    faces = np.array(analysis.surface.regular_faces)
    out = tmp_path / "run"
    out.mkdir()
    write_analysis(analysis, out, figures=False)
    assert "Normals" not in analysis.surface.cell_data
    assert np.array_equal(analysis.surface.regular_faces, faces)
    assert np.array_equal(pv.read(out / "surface.ply").regular_faces, faces)


def test_the_plan_records_the_peak_of_its_bands_not_its_limit():
    """A small stack's bands are the whole stack at any large limit: the peak the plan
    records is the same (it once followed the limit: rows counted before being cut to
    the stack's)."""
    from mpm3d import tiled

    kw = {"combined": False, "channels_read": 1, "surface": True, "bin": 1, "lazy": True}
    peaks = set()
    for limit in (2**30, 4 * 2**30):
        plan = plan_memory((59, 1, 96, 96), 2, limit=limit, **kw)
        for streamed in (True, False):
            meshed = tiled.plan_surface(plan, 44_140, iso_bin=1, streamed=streamed)
            assert meshed.surface_tile_rows == 95 and meshed.tiled_bytes < 2**30
            peaks.add((streamed, meshed.tiled_bytes))
    assert len(peaks) == 2  # one per kind of mesh, whatever the limit
