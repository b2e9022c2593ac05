"""Synthetic specimens: the ramp-hold contraction, its truth files and the study writer."""

import csv
import json

import cv2
import numpy as np
import pytest
from scipy import ndimage

from sample_data_synth import load_ground_truth, make_case
from sample_data_synth.cli import main
from sample_data_synth.deformations import (
    Contraction,
    Field,
    RampHold,
    deformation_from_dict,
    green_lagrange,
    time_profile_from_dict,
)
from sample_data_synth.specimens import (
    DEFAULT_DESIGN,
    Group,
    grid_nodal_strain,
    make_specimen,
    make_study,
    specimen_roi,
)
from tests.tolerances import (
    EXACT,
)
from tests.tolerances import (
    SPECIMEN_FINITE_DIFFERENCE as FINITE_DIFFERENCE,
)
from tests.tolerances import (
    SPECIMEN_LK_TRACK_PX as LK_TRACK_PX,
)
from tests.tolerances import (
    SPECIMEN_PULLBACK_SHIFT_PX as PULLBACK_SHIFT_PX,
)
from tissue_core.outputs import MARKER

TINY = (Group("anisotropic", 2, lx=0.80, ly=0.92), Group("isotropic", 2, lx=0.86, ly=0.86))
COLUMNS = [
    "run", "specimen", "group", "video", "truth", "true_lx", "true_ly", "true_endpoint", "roi"
]  # fmt: skip


def contraction() -> Contraction:
    c = (80.0, 70.0)
    return Contraction(
        c,
        lx=0.8,
        ly=0.9,
        fields=[
            Field("gaussian", (95.0, 60.0), a=0.05, s=20.0),
            Field("sinusoid", (130.0, 20.0), amplitude=1.0, wavelength=90.0),
        ],
    )


def test_contraction_forward_inverse_round_trip():
    d = contraction()
    X = np.random.default_rng(0).uniform(0, 160, (200, 2))
    for t in (0.0, 0.3, 1.0):
        x = d.forward(X, t)
        assert np.abs(d.inverse(x, t) - X).max() < EXACT
    assert np.abs(d.forward(X, 0.0) - X).max() < EXACT
    # the heterogeneity really moves points beyond the homogeneous map
    homogeneous = Contraction(d.center, lx=0.8, ly=0.9)
    assert np.abs(d.forward(X, 1.0) - homogeneous.forward(X, 1.0)).max() > 0.5


def test_contraction_gradient_matches_finite_differences():
    d = contraction()
    X = np.random.default_rng(1).uniform(20, 140, (50, 2))
    h = 1e-4
    for t in (0.4, 1.0):
        numeric = np.stack(
            [(d.forward(X + h * e, t) - d.forward(X - h * e, t)) / (2 * h) for e in np.eye(2)],
            axis=-1,
        )
        assert np.abs(numeric - d.gradient(X, t)).max() < FINITE_DIFFERENCE
        assert np.allclose(d.strain(X, t), green_lagrange(d.gradient(X, t)), atol=EXACT)


def test_contraction_dict_round_trip():
    d = contraction()
    back = deformation_from_dict(json.loads(json.dumps(d.to_dict())))
    assert isinstance(back, Contraction)
    X = np.random.default_rng(2).uniform(0, 160, (20, 2))
    assert np.array_equal(back.forward(X, 0.7), d.forward(X, 0.7))
    assert np.array_equal(back.gradient(X, 0.7), d.gradient(X, 0.7))


@pytest.mark.parametrize("kwargs", [{"lx": 0.0, "ly": 1.0}, {"lx": 1.0, "ly": np.nan}])
def test_contraction_rejects_bad_stretches(kwargs):
    with pytest.raises(ValueError, match=r"l[xy] must"):
        Contraction((0, 0), **kwargs)


def test_ramp_hold_profile():
    for ramp in ("smoothstep", "linear"):
        p = RampHold(8, ramp=ramp)
        t = np.array([p(k) for k in range(12)])
        assert t[0] == 0 and np.all(t[8:] == 1)
        assert np.all(np.diff(t[:9]) > 0)
        assert time_profile_from_dict(p.to_dict()) == p
    assert RampHold(4)(2) == 0.5
    assert RampHold(10, ramp="linear")(3) == pytest.approx(0.3)
    with pytest.raises(ValueError, match="endpoint"):
        RampHold(0)
    with pytest.raises(ValueError, match="ramp"):
        RampHold(3, ramp="cubic")


def test_homogeneous_specimen_strain_is_analytic_from_the_endpoint_on():
    lx, ly = 0.82, 0.93
    video = make_specimen(lx, ly, heterogeneity=0.0, endpoint=5, n_frames=9, size=96, rng=0)
    truth = video.truth
    grid = truth.grid()
    exact = np.array([[(lx**2 - 1) / 2, 0.0], [0.0, (ly**2 - 1) / 2]])
    for k in range(5, 9):
        assert np.abs(truth.strain(grid, k) - exact).max() < EXACT
        assert np.abs(grid_nodal_strain(truth, k) - exact).max() < EXACT
    assert np.abs(truth.strain(grid, 4) - exact).max() > 0.005  # not there yet


def test_positions_hold_after_the_endpoint_and_frames_hold_too():
    video = make_specimen(
        0.8, 0.9, endpoint=4, n_frames=7, size=96, read_noise=0, shot_gain=0, rng=3
    )
    truth = video.truth
    positions = truth.positions(truth.grid())
    assert np.all(np.diff(positions[4:], axis=0) == 0)
    assert np.all(np.abs(np.diff(positions[:5], axis=0)).max(axis=(1, 2)) > 0.1)
    # noise-free frames: identical from the endpoint on, different before it
    f = video.frames.astype(int)
    assert all(np.array_equal(f[4], f[k]) for k in (5, 6))
    assert np.abs(f[4] - f[3]).mean() > 1


def test_the_endpoint_detector_finds_the_endpoint():
    from strain2d.stats import contraction_endpoint

    for ramp in ("smoothstep", "linear"):
        video = make_specimen(0.8, 0.92, endpoint=16, n_frames=25, size=96, ramp=ramp, rng=1)
        E = grid_nodal_strain(video.truth)  # (T, N, 2, 2)
        curve = np.stack([E[:, :, 0, 0].mean(1), E[:, :, 1, 1].mean(1)], axis=1)
        assert contraction_endpoint(curve) == 16


def test_grid_nodal_strain_is_what_strain2d_computes_from_exact_tracks():
    from strain2d.pipeline import strain_from_tracks
    from strain2d.tracks import Tracks

    truth = make_specimen(0.8, 0.9, heterogeneity=0.1, n_frames=5, size=128, rng=4).truth
    positions = truth.positions(truth.grid())
    ones = np.ones(positions.shape[:2])
    field = strain_from_tracks(Tracks(positions, ones.astype(bool), ones), grid_shape=(7, 7))
    mine = grid_nodal_strain(truth)
    assert np.abs(field.nodal_E - mine).max() < EXACT
    # heterogeneous: nodal strains vary over the specimen
    assert mine[-1, :, 0, 0].std() > 0.01


def test_specimen_truth_json_round_trip(tmp_path):
    truth = make_specimen(0.8, 0.9, endpoint=3, n_frames=6, size=96, rng=5).truth
    truth.save(tmp_path / "t.json")
    back = load_ground_truth(tmp_path / "t.json")
    assert back.time_profile == truth.time_profile == RampHold(3)
    assert back.to_dict() == truth.to_dict()
    grid = truth.grid()
    assert np.array_equal(back.positions(grid), truth.positions(grid))
    d = json.loads((tmp_path / "t.json").read_text())
    assert d["time_profile"] == {"type": "ramp_hold", "endpoint": 3, "ramp": "smoothstep"}
    assert "ramp then hold" in d["time"]


def test_benchmark_truth_files_are_unchanged_and_still_load(tmp_path):
    truth = make_case("equibiaxial", size=64, n_frames=3).truth
    d = truth.to_dict()
    assert "time_profile" not in d
    assert d["time"] == "linear ramp: frame k has t = k / (n_frames - 1)"
    truth.save(tmp_path / "t.json")
    back = load_ground_truth(tmp_path / "t.json")
    assert back.time_profile is None and back.time(1) == 0.5


def pullback(frame: np.ndarray, truth, k: int, shift=(0.0, 0.0)) -> tuple[np.ndarray, tuple]:
    """Frame ``k`` sampled at the true current positions of the ROI's reference pixels."""
    x0, y0, x1, y1 = (int(v) for v in truth.roi)
    yy, xx = np.mgrid[y0 : y1 + 1, x0 : x1 + 1].astype(float)
    x = truth.positions(np.stack([xx, yy], -1).reshape(-1, 2), k) + np.asarray(shift)
    values = ndimage.map_coordinates(frame.astype(float), [x[:, 1], x[:, 0]], order=3)
    return values.reshape(xx.shape), (slice(y0, y1 + 1), slice(x0, x1 + 1))


def window_shift(ref: np.ndarray, moved: np.ndarray) -> np.ndarray:
    """Least-squares (Lucas-Kanade) shift ``s`` of the whole window, ``moved(X) = ref(X + s)``,
    by Gauss-Newton iterations (the 4 px border is left out)."""
    s = np.zeros(2)
    inner = (slice(4, -4), slice(4, -4))
    for _ in range(5):
        warped = ndimage.shift(ref, (-s[1], -s[0]), order=3, mode="nearest")
        gy, gx = np.gradient(warped)
        A = np.column_stack([gx[inner].ravel(), gy[inner].ravel()])
        s += np.linalg.lstsq(A, (moved - warped)[inner].ravel(), rcond=None)[0]
    return s


@pytest.mark.parametrize("texture", ["tissue", "speckle"])
def test_rendered_frames_move_as_the_truth_says(texture):
    video = make_specimen(
        0.8, 0.9, heterogeneity=0.06, endpoint=3, n_frames=5, size=160, texture=texture, rng=6
    )
    truth, frames = video.truth, video.frames
    for k in (2, 4):
        back, window = pullback(frames[k], truth, k)
        ref = frames[0][window].astype(float)
        assert np.hypot(*window_shift(ref, back)) < PULLBACK_SHIFT_PX
        # positions 0.5 px off along x are seen as F^-1 (0.5, 0) in the reference
        off, _ = pullback(frames[k], truth, k, shift=(0.5, 0.0))
        x0, y0, x1, y1 = truth.roi
        yy, xx = np.mgrid[y0 : y1 + 1, x0 : x1 + 1]
        F = truth.gradient(np.column_stack([xx.ravel(), yy.ravel()]), k)
        expected = (np.linalg.inv(F) @ [0.5, 0.0]).mean(axis=0)
        assert expected[0] > 0.55  # contracted along x: more than 0.5 reference px
        assert np.abs(window_shift(ref, off) - expected).max() < PULLBACK_SHIFT_PX
        # and the pulled-back frame matches the reference far better than the raw frame
        assert np.abs(back - ref).mean() < 0.3 * np.abs(frames[k][window] - ref).mean()
    # OpenCV's pyramidal Lucas-Kanade moves the true points of each frame to the true
    # points of the next
    grid = truth.grid((5, 5))
    for k in range(1, 4):
        start = truth.positions(grid, k - 1).astype(np.float32)[:, None]
        found, status, _ = cv2.calcOpticalFlowPyrLK(
            frames[k - 1], frames[k], start, None, winSize=(21, 21), maxLevel=2
        )
        assert status.all()
        error = np.linalg.norm(found[:, 0] - truth.positions(grid, k), axis=1)
        motion = np.linalg.norm(truth.positions(grid, k) - start[:, 0], axis=1)
        assert motion.max() > 2.5  # the frames really move
        assert np.median(error) < LK_TRACK_PX


def test_specimens_differ_by_seed_and_repeat_with_it():
    a = make_specimen(0.8, 0.9, n_frames=3, size=96, rng=7)
    b = make_specimen(0.8, 0.9, n_frames=3, size=96, rng=7)
    c = make_specimen(0.8, 0.9, n_frames=3, size=96, rng=8)
    assert np.array_equal(a.frames, b.frames)
    assert not np.array_equal(a.frames[0], c.frames[0])
    assert a.truth.deformation.to_dict() != c.truth.deformation.to_dict()  # heterogeneity phase


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"heterogeneity": 0.5}, "heterogeneity"),
        ({"endpoint": 9}, "endpoint"),
        ({"n_frames": 2}, "n_frames"),
        ({"size": 32}, "size"),
        ({"texture": "wood"}, "texture"),
        ({"lx": 1.6}, "frame edge"),
        ({"lx": -0.1}, "lx"),
    ],
)
def test_make_specimen_rejects_bad_arguments(kwargs, match):
    args = {"lx": 0.8, "ly": 0.9, "n_frames": 9, "size": 96, **kwargs}
    lx, ly = args.pop("lx"), args.pop("ly")
    with pytest.raises(ValueError, match=match):
        make_specimen(lx, ly, **args)


def test_default_design():
    groups = {g.name: g for g in DEFAULT_DESIGN}
    assert groups["anisotropic"].lx < groups["anisotropic"].ly
    assert groups["anisotropic"].expected == "Exx differs from Eyy"
    assert groups["isotropic"].lx == groups["isotropic"].ly
    assert groups["isotropic"].expected == "no difference"
    assert sum(g.n for g in DEFAULT_DESIGN) == 8


@pytest.fixture(scope="module")
def tiny_study(tmp_path_factory):
    out = tmp_path_factory.mktemp("study") / "s"
    result = make_study(out, design=TINY, size=96, n_frames=9, rng=11)
    return out, result


def test_study_manifest(tiny_study):
    out, _ = tiny_study
    with open(out / "manifest.csv", newline="") as f:
        reader = csv.DictReader(f)
        assert reader.fieldnames == COLUMNS
        rows = list(reader)
    assert [r["specimen"] for r in rows] == ["S01", "S02", "S03", "S04"]
    assert [r["group"] for r in rows] == ["anisotropic"] * 2 + ["isotropic"] * 2
    assert (out / "runs").is_dir()
    assert specimen_roi(96) == (19.0, 19.0, 76.0, 76.0)
    for r in rows:
        assert r["run"] == f"runs/{r['specimen']}"
        assert r["roi"] == "19,19,76,76"
        assert (out / r["video"]).is_file() and r["video"].endswith(".avi")
        truth = load_ground_truth(out / r["truth"])
        assert truth.params["lx"] == float(r["true_lx"])
        assert truth.params["ly"] == float(r["true_ly"])
        assert truth.time_profile.endpoint == int(r["true_endpoint"])
        assert 4 <= int(r["true_endpoint"]) <= 6  # 55 % to 75 % of frames 0..8
        assert truth.roi == specimen_roi(96)
        cap = cv2.VideoCapture(str(out / r["video"]))  # lossless: the frames come back exactly
        ok, first = cap.read()
        cap.release()
        assert ok and first.shape[:2] == (96, 96)
    lxs = [float(r["true_lx"]) for r in rows]
    assert len(set(lxs)) == 4  # specimen-to-specimen variability


def test_study_truth(tiny_study):
    out, result = tiny_study
    saved = json.loads((out / "study_truth.json").read_text())
    assert saved == json.loads(json.dumps(result))
    for s in saved["specimens"]:
        truth = load_ground_truth(out / s["truth"])
        nodal = grid_nodal_strain(truth, s["endpoint"])
        assert s["Exx"] == pytest.approx(nodal[:, 0, 0].mean(), abs=EXACT)
        assert s["Eyy"] == pytest.approx(nodal[:, 1, 1].mean(), abs=EXACT)
        continuum = truth.strain(truth.grid(), s["endpoint"])
        assert s["Exx_continuum"] == pytest.approx(continuum[:, 0, 0].mean(), abs=EXACT)
        assert len(s["curve"]["Exx"]) == 9 and s["curve"]["Eyy"][-1] == pytest.approx(s["Eyy"])
        npz = np.load(out / f"{s['specimen']}_truth.npz")
        assert np.abs(npz["E_nodal"][s["endpoint"]] - nodal).max() < EXACT
    groups = saved["groups"]
    assert groups["anisotropic"]["expected"] == "Exx differs from Eyy"
    assert groups["anisotropic"]["expected_direction"] == "Exx < Eyy"
    assert groups["anisotropic"]["difference_mean"] < -0.05
    assert groups["isotropic"]["expected"] == "no difference"
    assert abs(groups["isotropic"]["difference_mean"]) < 0.03
    assert groups["isotropic"]["specimens"] == ["S03", "S04"]


def test_default_study_truth_gives_the_expected_verdicts(tmp_path):
    """On the exact specimen means, the default seed's groups test as designed."""
    result = make_study(tmp_path / "s", size=96, n_frames=5, rng=0)
    groups = result["groups"]
    assert groups["anisotropic"]["exact_paired_t"]["p"] < 0.05
    assert groups["isotropic"]["exact_paired_t"]["p"] > 0.05


def test_make_study_rejects_bad_designs(tmp_path):
    with pytest.raises(ValueError, match="unique"):
        make_study(tmp_path / "a", design=(TINY[0], TINY[0]), size=96, n_frames=5)
    with pytest.raises(ValueError, match="endpoint_range"):
        make_study(tmp_path / "b", design=TINY, endpoint_range=(0.8, 0.5))
    with pytest.raises(ValueError, match="n must"):
        Group("g", 0, lx=0.8, ly=0.9)
    with pytest.raises(ValueError, match="group name"):
        Group("a,b", 2, lx=0.8, ly=0.9)
    assert not (tmp_path / "a").exists()


def test_cli_study_end_to_end(tmp_path, capsys):
    out = tmp_path / "study"
    args = ["study", "--out", str(out), "--size", "96", "--frames", "5", "--per-group", "1"]
    assert main([*args, "--seed", "3"]) == 0
    err = capsys.readouterr().err
    assert "] rendering 2 specimens x 5 frames: 10/10 frames in " in err
    assert err.splitlines()[-1].endswith(f"] results in {out}")
    names = sorted(p.name for p in out.iterdir())
    assert names == [
        MARKER,
        "S01.avi",
        "S01_truth.json",
        "S01_truth.npz",
        "S02.avi",
        "S02_truth.json",
        "S02_truth.npz",
        "manifest.csv",
        "runs",
        "study_truth.json",
    ]
    first = json.loads((out / "study_truth.json").read_text())
    assert first["seed"] == 3 and [g["n"] for g in first["design"]["groups"]] == [1, 1]
    # existing output: one line, exit 2, nothing touched
    assert main([*args, "-q"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--overwrite" in err
    assert main([*args, "-q", "--overwrite", "--seed", "4"]) == 0
    second = json.loads((out / "study_truth.json").read_text())
    assert second["seed"] == 4 and second["specimens"] != first["specimens"]
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]  # no temp left


@pytest.mark.parametrize(
    "bad",
    [["--texture", "wood"], ["--per-group", "0"], ["--frames", "2"], ["--heterogeneity", "1"]],
)
def test_cli_study_bad_options(tmp_path, capsys, bad):
    assert main(["study", "--out", str(tmp_path / "s"), "-q", *bad]) == 2
    err = capsys.readouterr().err
    assert err.startswith("sample_data_synth study: error:") and err.count("\n") == 1
    assert not (tmp_path / "s").exists()
