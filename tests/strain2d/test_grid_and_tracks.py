import numpy as np
import pytest

from strain2d.errors import InputError
from strain2d.grid import make_grid, parse_grid, parse_roi, read_points_csv, validate_points
from strain2d.tracks import Tracks, read_tracks, write_tracks_csv


def test_grid_spans_the_roi_row_major():
    pts = make_grid((100, 200), shape=(4, 3), roi=(10, 20, 40, 60))
    assert pts.shape == (12, 2)
    np.testing.assert_allclose(pts[0], [10, 20])
    np.testing.assert_allclose(pts[3], [40, 20])
    np.testing.assert_allclose(pts[-1], [40, 60])
    default = make_grid((101, 201))
    np.testing.assert_allclose(default[0], [30, 15])
    np.testing.assert_allclose(default[-1], [170, 85])


@pytest.mark.parametrize("roi", [(-1, 0, 10, 10), (0, 0, 100, 10), (5, 5, 5, 9)])
def test_roi_outside_or_empty_is_refused(roi):
    with pytest.raises(InputError, match="roi"):
        make_grid((50, 100), roi=roi)


def test_parsers():
    assert parse_grid("7x5") == (7, 5)
    assert parse_roi("1,2,3.5,4") == (1, 2, 3.5, 4)
    for bad in ("7", "ax7", "1x7"):
        with pytest.raises(InputError):
            parse_grid(bad)
    with pytest.raises(InputError):
        parse_roi("1,2,3")


def test_points_csv(tmp_path):
    p = tmp_path / "p.csv"
    p.write_text("X, Y\n1,2\n3.5,4\n")
    np.testing.assert_allclose(read_points_csv(p), [[1, 2], [3.5, 4]])
    p.write_text("a,b\n1,2\n")
    with pytest.raises(InputError, match="x,y"):
        read_points_csv(p)
    p.write_text("x,y\n1,oops\n")
    with pytest.raises(InputError, match="numbers"):
        read_points_csv(p)


def test_validate_points():
    with pytest.raises(InputError, match="at least 3"):
        validate_points(np.zeros((2, 2)))
    with pytest.raises(InputError, match="collinear"):
        validate_points(np.array([[0, 0], [1, 1], [2, 2.0]]))
    with pytest.raises(InputError, match="outside"):
        validate_points(np.array([[0, 0], [1, 0], [0, 60.0]]), (50, 50))


def _tracks():
    rng = np.random.default_rng(0)
    pos = rng.uniform(0, 100, (4, 5, 2))
    vis = rng.random((4, 5)) > 0.3
    vis[0] = True
    return Tracks(pos, vis, rng.random((4, 5)), {"tracker": "test"})


@pytest.mark.parametrize("suffix", [".csv", ".npz"])
def test_tracks_round_trip(tmp_path, suffix):
    tracks = _tracks()
    path = tmp_path / f"t{suffix}"
    if suffix == ".csv":
        write_tracks_csv(path, tracks)
        assert path.read_text().splitlines()[0] == "frame,point,x,y,visible,quality"
    else:
        np.savez(path, positions=tracks.positions, visible=tracks.visible, quality=tracks.quality)
    back = read_tracks(path)
    np.testing.assert_allclose(back.positions, tracks.positions, atol=1e-6)
    np.testing.assert_array_equal(back.visible, tracks.visible)
    np.testing.assert_allclose(back.quality, tracks.quality, rtol=1e-5)


def test_tracks_uncertainty_round_trips_through_csv_npz_and_the_imported_tracker(tmp_path):
    from strain2d import track

    tracks = _tracks()
    sigma = np.random.default_rng(1).uniform(0.01, 0.5, (4, 5))
    sigma[0] = 0.0
    tracks = Tracks(tracks.positions, tracks.visible, tracks.quality, {}, sigma)
    write_tracks_csv(tmp_path / "t.csv", tracks)
    np.savez(tmp_path / "t.npz", positions=tracks.positions, uncertainty_px=sigma)
    for name in ("t.csv", "t.npz"):
        back = read_tracks(tmp_path / name)
        np.testing.assert_allclose(back.uncertainty, sigma, rtol=5e-4)  # CSV: 4 digits
        imported = track(None, tracks.positions[0, [3, 1, 4]], tracker="imported",
                         options={"tracks_file": tmp_path / name})  # fmt: skip
        np.testing.assert_allclose(imported.uncertainty, sigma[:, [3, 1, 4]], rtol=5e-4)
    np.savez(tmp_path / "bad.npz", positions=tracks.positions, uncertainty=sigma[:2])
    with pytest.raises(InputError, match="uncertainty must have shape"):
        read_tracks(tmp_path / "bad.npz")
    np.savez(tmp_path / "neg.npz", positions=tracks.positions, uncertainty=-sigma)
    write_tracks_csv(tmp_path / "neg.csv", Tracks(tracks.positions, tracks.visible,
                                                  tracks.quality, {}, -sigma))  # fmt: skip
    for name in ("neg.npz", "neg.csv"):
        with pytest.raises(InputError, match="must not be negative"):
            read_tracks(tmp_path / name)


def test_tracks_npy_and_bad_files(tmp_path):
    tracks = _tracks()
    np.save(tmp_path / "t.npy", tracks.positions)
    back = read_tracks(tmp_path / "t.npy")
    assert back.visible.all()
    (tmp_path / "t.csv").write_text("frame,point,x,y\n0,0,1,2\n0,0,1,2\n")
    with pytest.raises(InputError, match="exactly one row"):
        read_tracks(tmp_path / "t.csv")
    (tmp_path / "u.csv").write_text("frame,x,y\n0,1,2\n")
    with pytest.raises(InputError, match="point"):
        read_tracks(tmp_path / "u.csv")
    with pytest.raises(InputError, match="shape"):
        Tracks(np.zeros((2, 3)), np.ones((2, 3), bool), np.ones((2, 3)))
