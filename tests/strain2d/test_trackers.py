import numpy as np
import pytest

from sample_data_synth import make_case
from strain2d import available_trackers, track
from strain2d.errors import InputError
from strain2d.grid import make_grid
from strain2d.pipeline import strain_from_tracks
from strain2d.tracks import write_tracks_csv
from tests.tolerances import KLT_EQUIBIAXIAL_STRAIN, KLT_QUICK_TRACK_RMSE_PX, KLT_RIGID_STRAIN


def test_registry_lists_the_built_in_trackers():
    trackers = available_trackers()
    assert {"klt", "imported"} <= set(trackers)
    assert trackers["klt"].needs_frames and not trackers["imported"].needs_frames
    with pytest.raises(InputError, match="unknown tracker"):
        track(None, None, tracker="nope")


def test_klt_recovers_the_paper_equibiaxial_strain(paper_equibiaxial):
    """Done-when of the foundation: Exx = Eyy = 0.625 within 0.01 on the 800 px video."""
    from strain2d.frames import open_frames

    path, video = paper_equibiaxial
    source = open_frames(path)
    points = video.truth.grid((7, 7))
    tracks = track(source, points, tracker="klt")
    field = strain_from_tracks(tracks)
    assert tracks.visible.all()
    for comp, true in ((0, 0.625), (1, 0.625)):
        error = field.nodal_E[-1, :, comp, comp] - true
        assert abs(error.mean()) < KLT_EQUIBIAXIAL_STRAIN
        assert np.sqrt(np.mean(error**2)) < KLT_EQUIBIAXIAL_STRAIN
    assert np.sqrt(np.mean(field.nodal_E[-1, :, 0, 1] ** 2)) < KLT_EQUIBIAXIAL_STRAIN


@pytest.mark.parametrize("case", ["rotation", "shear", "tissue"])
def test_klt_tracks_the_other_paper_cases(case):
    video = make_case(case, size=400, n_frames=11, rng=2)
    points = video.truth.grid((7, 7))
    tracks = track(video.frames, points, tracker="klt")
    err = np.linalg.norm(tracks.positions[-1] - video.truth.positions(points, 10), axis=1)
    assert tracks.visible[-1].all()
    assert np.sqrt(np.mean(err**2)) < KLT_QUICK_TRACK_RMSE_PX


def test_window_bias_correction_is_what_makes_klt_accurate():
    video = make_case("rotation", size=400, n_frames=11, rng=3)
    points = video.truth.grid((7, 7))
    truth = video.truth.positions(points, 10)

    def rmse(**opts):
        tr = track(video.frames, points, tracker="klt", options=opts)
        return np.sqrt(np.mean(np.sum((tr.positions[-1] - truth) ** 2, axis=1)))

    assert rmse(affine_correction=True) < 0.5 * rmse(affine_correction=False)


def test_klt_rigid_translation_gives_zero_strain():
    rng = np.random.default_rng(0)
    from scipy import ndimage

    big = ndimage.gaussian_filter(rng.uniform(0, 255, (300, 300)), 1.5)
    big = (big - big.min()) / np.ptp(big) * 255
    frames = np.stack(
        [ndimage.shift(big, (0.7 * k, -1.3 * k), order=3)[50:250, 50:250] for k in range(8)]
    )
    points = make_grid((200, 200), shape=(5, 5), roi=(50, 50, 150, 150))
    tracks = track(frames.astype(np.uint8), points, tracker="klt")
    field = strain_from_tracks(tracks)
    np.testing.assert_allclose(tracks.positions[-1] - points, [[-1.3 * 7, 0.7 * 7]] * 25, atol=0.1)
    assert np.abs(field.nodal_E[-1]).max() < KLT_RIGID_STRAIN


def test_klt_marks_points_lost_when_texture_vanishes():
    video = make_case("equibiaxial", size=200, n_frames=6, rng=4)
    frames = video.frames.copy()
    frames[3:, :100, :100] = 128  # the top-left quarter loses its texture from frame 3 on
    points = video.truth.grid((4, 4))
    tracks = track(frames, points, tracker="klt")
    lost = ~tracks.visible[-1]
    in_quarter = (points[:, 0] < 90) & (points[:, 1] < 90)
    assert lost[in_quarter].all()
    assert not lost[~in_quarter & ((points[:, 0] > 110) | (points[:, 1] > 110))].any()
    assert (tracks.quality[-1][lost] == 0).all()
    field = strain_from_tracks(tracks)
    has_valid_triangle = np.zeros(len(points), bool)
    has_valid_triangle[field.triangles[field.element_valid[-1]].ravel()] = True
    assert has_valid_triangle.any()
    assert np.isfinite(field.nodal_E[-1][has_valid_triangle]).all()
    assert np.isnan(field.nodal_E[-1][~has_valid_triangle]).all()


def test_klt_bad_options():
    frames = np.zeros((3, 50, 50), np.uint8)
    pts = np.array([[10.0, 10], [30, 10], [10, 30]])
    with pytest.raises(InputError, match="window"):
        track(frames, pts, tracker="klt", options={"window": 4})
    with pytest.raises(InputError, match="unexpected keyword"):
        track(frames, pts, tracker="klt", options={"tracks_file": "x"})


def test_imported_tracks_select_requested_points(tmp_path):
    video = make_case("shear", size=200, n_frames=4, rng=0)
    grid = video.truth.grid((3, 3))
    truth = video.truth.positions(grid)
    from strain2d.tracks import Tracks

    write_tracks_csv(tmp_path / "t.csv", Tracks(truth, np.ones((4, 9), bool), np.ones((4, 9))))
    all_tracks = track(
        video.frames, None, tracker="imported", options={"tracks_file": tmp_path / "t.csv"}
    )
    np.testing.assert_allclose(all_tracks.positions, truth, atol=1e-6)
    some = track(
        video.frames,
        grid[[4, 0, 2]] + 0.3,
        tracker="imported",
        options={"tracks_file": tmp_path / "t.csv"},
    )
    np.testing.assert_allclose(some.positions, truth[:, [4, 0, 2]], atol=1e-6)
    field = strain_from_tracks(all_tracks)
    np.testing.assert_allclose(field.nodal_E[-1, :, 0, 1], 0.25, atol=1e-6)
    with pytest.raises(InputError, match="no imported track"):
        track(
            video.frames,
            grid[[0, 1, 3]] + 5,
            tracker="imported",
            options={"tracks_file": tmp_path / "t.csv"},
        )
    with pytest.raises(InputError, match="holds 4 frames"):
        track(
            video.frames[:3], None, tracker="imported", options={"tracks_file": tmp_path / "t.csv"}
        )
    with pytest.raises(InputError, match="tracks-file"):
        track(video.frames, None, tracker="imported")


def test_grid_meshes_cell_by_cell():
    from strain2d.errors import InputError as Err
    from strain2d.tracks import Tracks

    grid = make_grid((100, 100), shape=(4, 3), roi=(10, 10, 70, 50))
    tracks = Tracks(np.stack([grid, grid * 1.1]), np.ones((2, 12), bool), np.ones((2, 12)))
    field = strain_from_tracks(tracks, grid_shape=(4, 3))
    assert field.n_triangles == 2 * 3 * 2
    np.testing.assert_allclose(field.nodal_E[1, :, 0, 0], 0.5 * (1.1**2 - 1))
    with pytest.raises(Err, match="4x4 grid has 16 points"):
        strain_from_tracks(tracks, grid_shape=(4, 4))


def _speckle(size, seed):
    from scipy import ndimage

    rng = np.random.default_rng(seed)
    img = ndimage.gaussian_filter(rng.uniform(0, 255, (size, size)), 1.5)
    return (img - img.min()) / np.ptp(img) * 255


def test_klt_loses_points_whose_window_leaves_the_image():
    from scipy import ndimage

    big = _speckle(400, 5)
    frames = np.stack(
        [ndimage.shift(big, (0, 3.0 * k), order=3)[100:300, 100:300] for k in range(20)]
    ).astype(np.uint8)
    points = np.array([[150.0, 60], [150, 140], [100, 100], [40, 100]])
    tracks = track(frames, points, tracker="klt", options={"window": 21})
    # x + 3 k passes 200 - 1 - 10 (the window's half) for the first two points
    assert not tracks.visible[-1, :2].any()
    assert tracks.visible[-1, 2:].all()
    first_lost = np.argmax(~tracks.visible[:, 0])
    assert 150 + 3 * first_lost > 189 >= 150 + 3 * (first_lost - 1)


def test_klt_velocity_prediction_follows_accelerating_motion():
    """Without a pyramid, 2 px more per frame is only trackable from the predicted position."""
    from scipy import ndimage

    big = _speckle(400, 6)
    shifts = np.cumsum([0, 1, 3, 5, 7, 9, 11])  # steps grow by 2 px
    frames = np.stack(
        [ndimage.shift(big, (0, s), order=3)[50:350, 20 : 380 - 40] for s in shifts]
    ).astype(np.uint8)
    points = make_grid(frames.shape[1:], shape=(3, 3), roi=(40, 60, 120, 240))
    tracks = track(frames, points, tracker="klt", options={"levels": 0, "window": 15})
    assert tracks.visible.all()
    np.testing.assert_allclose(tracks.positions[-1, :, 0] - points[:, 0], shifts[-1], atol=0.1)


def test_a_tracker_declares_its_options_and_the_command_line_offers_them(
    small_case, tmp_path, capsys
):
    """Adding a tracker touches one file: its options become flags of track and analyze."""
    from strain2d import trackers as registry
    from strain2d.cli import main
    from strain2d.tracks import Tracks, read_tracks

    seen = {}

    @registry.register_tracker(
        "still",
        description="every point stays where it was (a test tracker)",
        options=[
            registry.TrackerOption("jitter", "--jitter", "offset in px (default 0)", type=float),
            registry.TrackerOption("mark", "--mark", "flag lost points", switch=True),
        ],
    )
    def track_still(frames, points, *, jitter=0.0, mark=False, progress=None):
        seen.update(jitter=jitter, mark=mark)
        n = sum(1 for _ in frames)
        pos = np.repeat(points[None], n, axis=0) + jitter
        return Tracks(pos, np.ones(pos.shape[:2], bool), np.ones(pos.shape[:2]))

    try:
        folder, _ = small_case
        out = tmp_path / "t.csv"
        argv = ["track", str(folder / "eq.tif"), "--grid", "3x3", "--tracker", "still"]
        assert main([*argv, "--jitter", "0.5", "--mark", "--out", str(out), "-q"]) == 0
        assert seen == {"jitter": 0.5, "mark": True}
        tracks = read_tracks(out)
        assert np.allclose(tracks.positions[-1] - tracks.positions[0], 0.0)
        assert main([*argv, "--jitter", "half", "--out", str(tmp_path / "u.csv")]) == 2
        assert "--jitter must be a number, got 'half'" in capsys.readouterr().err
        klt = ["track", str(folder / "eq.tif"), "--tracker", "klt", "--jitter", "1"]
        assert main([*klt, "--out", str(tmp_path / "v.csv")]) == 2
        assert "--jitter does not apply to the klt tracker" in capsys.readouterr().err
    finally:
        registry._REGISTRY.pop("still", None)


def test_a_declared_option_must_be_a_parameter_of_the_tracker():
    from strain2d import trackers as registry

    with pytest.raises(ValueError, match="no parameter 'gain'"):
        registry.register_tracker(
            "broken", description="-", options=[registry.TrackerOption("gain", "--gain", "-")]
        )(lambda frames, points, *, progress=None: None)
    assert "broken" not in registry.available_trackers()


@pytest.mark.parametrize(
    ("tracker", "value", "message"),
    [
        ("gdic", "x", "--subset must be auto or a whole number of pixels, got 'x'"),
        ("dic", "auto", "--subset must be a whole number of pixels for the dic tracker (auto "),
        ("klt", "x", "--window must be a whole number, got 'x'"),
    ],
)
def test_bad_tracker_option_values_fail_before_anything_is_read(
    tracker, value, message, tmp_path, capsys
):
    from strain2d.cli import main

    flag = "--window" if tracker == "klt" else "--subset"
    missing = tmp_path / "no_such_video.avi"  # the option is judged first
    assert main(["track", str(missing), "--tracker", tracker, flag, value,
                 "--out", str(tmp_path / "t.csv")]) == 2  # fmt: skip
    assert message in capsys.readouterr().err
