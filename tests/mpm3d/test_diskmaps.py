"""(Y, X) maps on disk: each step a band or a strip at a time, the in-memory values bit for bit.

The maps are small and the bands and strips a few lines each, so that every
band boundary, every edge and every strip of the padding is crossed.
"""

import os
import warnings

import numpy as np
import pytest

from mpm3d.diskmaps import (
    DiskMap,
    MapFolder,
    exact_median,
    exact_percentiles,
    fill_gaps_on_disk,
    from_crossings_on_disk,
    smooth_on_disk,
)
from mpm3d.errors import InputError
from mpm3d.heightmap import fill_gaps, from_crossings, smooth_map


def _crossings(rng, ny: int, nx: int, big_gap: bool):
    """Crossing depth (slices) and peak maps with drop-outs, a cut-off patch, spikes and
    faint columns."""
    yy, xx = np.mgrid[0:ny, 0:nx]
    depth = 10 + 3 * np.sin(xx / 7.0) + 0.02 * yy + rng.normal(0, 0.1, (ny, nx))
    peak = 100 + 50 * rng.random((ny, nx))
    depth[rng.random((ny, nx)) < 0.2] = np.nan
    if big_gap:  # wider than the first fill's kernel: the fill grows over several rounds
        depth[5:15, 3:40] = np.nan
    depth[rng.random((ny, nx)) < 0.01] = -1.0
    depth[rng.random((ny, nx)) < 0.02] += 30.0
    peak[rng.random((ny, nx)) < 0.05] = 52.0
    return depth, peak


@pytest.mark.parametrize("seed", range(6))
def test_height_map_from_maps_on_disk_is_the_in_memory_one(seed):
    rng = np.random.default_rng(seed)
    ny, nx = (int(n) for n in rng.integers(20, 90, 2))
    depth, peak = _crossings(rng, ny, nx, big_gap=seed % 2 == 1)
    options = {
        "spacing": (2.0, 1.5, 1.2),
        "n_slices": 40,
        "levels": (60.0, 50.0, 2.0),
        "threshold_given": False,
        "separability": 0.5,
        "peak_window_um": 20.0,
        "smooth_um": (0.0, 1.2, 5.0)[seed % 3],
        "min_cnr": 5.0,
        "outlier_um": None,
        "min_coverage": 0.05,
    }
    band, strip = (int(n) for n in rng.integers(1, 9, 2))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        expected = from_crossings(depth, peak, **options)
        with MapFolder() as folder:
            got = from_crossings_on_disk(
                DiskMap.of(folder, depth), DiskMap.of(folder, peak), folder,
                band=band, strip=strip, **options,
            )  # fmt: skip
            left = sorted(p.name.split("-", 1)[1] for p in folder.path.iterdir())
    for name in ("depth_um", "valid", "cnr", "peak"):
        a, b = getattr(expected, name), getattr(got, name)
        assert a.dtype == b.dtype and np.array_equal(a, b), name
    assert got.level == expected.level
    assert got.dropouts == expected.dropouts
    assert got.params == expected.params
    assert expected.dropouts["outlier"] > 0 and expected.dropouts["above_stack"] > 0
    # the work maps are removed as soon as done: the two inputs and the maps read at the end
    final = "smoothed.bin" if options["smooth_um"] else "filled.bin"
    assert left == sorted(["map.bin", "map.bin", "valid.bin", "cnr.bin", final])


@pytest.mark.parametrize(
    ("shape", "sigma"),
    [((37, 23), (1.0, 2.5)), ((9, 60), (6.0, 0.0)), ((50, 3), (0.7, 9.0)),
     ((1, 1), (2.0, 2.0)), ((1, 2), (2.0, 2.0)), ((1, 30), (3.0, 3.0)), ((2, 1), (1.0, 1.0)),
     ((30, 1), (3.0, 3.0)), ((5, 2), (1.5, 1.5))],
)  # fmt: skip
def test_smoothing_and_filling_on_disk_are_the_in_memory_ones(shape, sigma):
    rng = np.random.default_rng(1)
    values = rng.normal(size=shape).cumsum(axis=1)
    valid = rng.random(shape) > 0.4
    with MapFolder() as folder:
        on_disk = DiskMap.of(folder, values)
        for band, strip in ((1, 1), (4, 7), (None, None)):
            smooth = smooth_on_disk(on_disk, sigma, folder, band=band, strip=strip)
            assert np.array_equal(smooth.to_array(), smooth_map(values, sigma))
            filled = fill_gaps_on_disk(on_disk, DiskMap.of(folder, valid), folder, band=band,
                                       strip=strip)  # fmt: skip
            assert np.array_equal(filled.to_array(), fill_gaps(values, valid))


def test_filling_nothing_is_refused():
    with MapFolder() as folder:
        values = DiskMap.of(folder, np.ones((4, 4)))
        with pytest.raises(InputError, match="nothing to fill"):
            fill_gaps_on_disk(values, DiskMap.of(folder, np.zeros((4, 4), bool)), folder)


@pytest.mark.parametrize("n", [1, 2, 3, 8, 1001])
def test_exact_median_is_numpys(n):
    rng = np.random.default_rng(n)
    values = np.round(rng.normal(size=n) * 4) / 3  # ties, negatives and zeros
    values[: n // 4] = -(values[: n // 4] ** 2) - 1e300 * (n > 8)
    parts = np.array_split(values, 4)
    assert exact_median(lambda: iter(parts), n) == np.median(values)


def test_map_folder_is_removed_and_asks_for_the_space_it_needs(tmp_path, monkeypatch):
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", None)
    with MapFolder(1000) as folder:
        m = folder.new((3, 5), np.float32)
        m.write_rows(1, np.ones((2, 5), np.float32))
        assert m.rows(0, 3).sum() == 10 and m.columns(2, 4).shape == (3, 2)
        assert folder.path.parent == tmp_path
    assert not folder.path.exists()
    with pytest.raises(InputError, match="TMPDIR"):
        MapFolder(1 << 62)
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize("n", [1, 2, 5, 29, 1000])
def test_exact_percentiles_are_numpys(n):
    rng = np.random.default_rng(n)
    for values in (rng.normal(size=n) * 1e3, np.round(rng.normal(size=n))):
        q = [0, 1, 50, 99, 100, 100 * rng.random()]
        parts = np.array_split(values, 3)
        assert np.array_equal(
            exact_percentiles(lambda p=parts: iter(p), n, q), np.percentile(values, q)
        )


def test_a_full_disk_is_a_clear_error_before_any_page_is_written(monkeypatch):
    """The maps' blocks are reserved when made: a full disk is an InputError there (a page
    of a memory map written to a sparse file on a full disk ends the process: SIGBUS)."""
    import errno

    def full(fd, offset, length):
        raise OSError(errno.ENOSPC, "No space left on device")

    with MapFolder() as folder:
        monkeypatch.setattr(os, "posix_fallocate", full)
        with pytest.raises(InputError, match=r"no disk space left .* TMPDIR"):
            folder.new((64, 64), np.float64)

        def unsupported(fd, offset, length):
            raise OSError(errno.EOPNOTSUPP, "Operation not supported")

        monkeypatch.setattr(os, "posix_fallocate", unsupported)
        sparse = folder.new((4, 4), np.float32)  # a file system that reserves nothing
        assert sparse.to_array().sum() == 0 and sparse.path.stat().st_size == 64
        monkeypatch.delattr(os, "posix_fallocate")  # as on macOS and Windows
        sparse = folder.new((2, 3), np.float64)
        assert sparse.to_array().sum() == 0 and sparse.path.stat().st_size == 48


def test_the_disk_space_asked_for_covers_the_work_maps_at_their_peak(monkeypatch):
    """The space :func:`mpm3d.tiled.disk_bytes` asks for is never exceeded, with a
    smoothing whose extension past the edges is larger than the map."""
    import mpm3d.diskmaps as diskmaps
    from mpm3d.tiled import disk_bytes

    rng = np.random.default_rng(4)
    depth, peak = _crossings(rng, 40, 50, big_gap=True)
    spacing = (2.0, 1.5, 1.2)
    made = diskmaps.DiskMap.__init__
    peak_bytes = [0]

    def counting(self, path, shape, dtype):
        made(self, path, shape, dtype)
        used = sum(p.stat().st_size for p in self.path.parent.iterdir())
        peak_bytes[0] = max(peak_bytes[0], used)

    monkeypatch.setattr(diskmaps.DiskMap, "__init__", counting)
    for smooth in (0.0, 1.2, 40.0):
        peak_bytes[0] = 0
        with warnings.catch_warnings(), MapFolder() as folder:
            warnings.simplefilter("ignore")
            from_crossings_on_disk(
                DiskMap.of(folder, depth), DiskMap.of(folder, peak), folder, spacing=spacing,
                n_slices=40, levels=(60.0, 50.0, 2.0), threshold_given=False, separability=0.5,
                peak_window_um=20.0, smooth_um=smooth, min_cnr=5.0, outlier_um=None,
                min_coverage=0.05,
            )  # fmt: skip
        asked = disk_bytes(depth.shape, spacing, smooth)
        assert 0 < peak_bytes[0] <= asked, (smooth, peak_bytes[0], asked)
    assert peak_bytes[0] > 69 * depth.size  # the wide smoothing's extension counted


def test_work_folder_warnings(tmp_path, monkeypatch):
    import tempfile

    import mpm3d.diskmaps as diskmaps
    from mpm3d.errors import WorkFolderWarning

    # a TMPDIR that cannot be used: Python picks another folder, and says so here
    monkeypatch.setenv("TMPDIR", str(tmp_path / "missing"))
    monkeypatch.setattr(tempfile, "tempdir", None)
    with pytest.warns(WorkFolderWarning, match="is not a folder this process can write to"):
        MapFolder(10).close()
    # a folder held in memory: its maps take memory the limit does not count
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    monkeypatch.setattr(tempfile, "tempdir", None)
    monkeypatch.setattr(diskmaps, "_in_memory", lambda folder: True)
    with pytest.warns(WorkFolderWarning, match="held in memory"):
        MapFolder(10).close()


def test_in_memory_file_systems_are_told_from_the_mount_table(monkeypatch):
    from pathlib import Path

    import mpm3d.diskmaps as diskmaps

    table = "\n".join([
        "/dev/vda / ext4 rw 0 0",
        "tmpfs /tmp tmpfs rw 0 0",
        "/dev/vdb /tmp/big ext4 rw 0 0",
        "tmpfs /run/my\\040dir tmpfs rw 0 0",
    ])  # fmt: skip
    read = Path.read_text
    monkeypatch.setattr(
        Path,
        "read_text",
        lambda self, *a, **k: table if str(self) == "/proc/mounts" else read(self, *a, **k),
    )
    monkeypatch.setattr(diskmaps.os.path, "realpath", lambda p: str(p))
    assert diskmaps._in_memory("/tmp") and diskmaps._in_memory("/tmp/work")
    assert not diskmaps._in_memory("/tmp/big/work") and not diskmaps._in_memory("/tmpx")
    assert not diskmaps._in_memory("/home") and diskmaps._in_memory("/run/my dir/x")
