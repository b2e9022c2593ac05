"""The cotracker3 adapter, driven end to end by a stand-in predictor (no network, no weights).

The stand-in (``cotracker_standin.py``) honours the published predictor's contract
and moves points along ``x(t) = A + L**t (X - A)`` about a marker ``A`` it finds
in the video itself, working at 384 x 512 like the real model; see its docstring.
"""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from strain2d import track
from strain2d.cli import main
from strain2d.errors import InputError
from strain2d.grid import make_grid
from strain2d.trackers.cotracker import _device, crop_box, load_cotracker3, track_cotracker
from tests.badinput import message_lines
from tests.strain2d import cotracker_standin
from tests.strain2d.cotracker_standin import StandInPredictor
from tests.tolerances import COTRACKER_STANDIN_PX

SHAPE = (240, 320)  # H, W
ANCHOR = np.array([150.0, 110.0])  # the marker's centre (x, y)
LOG_STRETCH = np.log([1.02, 0.985])  # per frame
ROI = (100, 70, 200, 150)
OCCLUDER = (190, 0, 320, 100)  # x0, y0, x1, y1 (exclusive), black in the windows below
WINDOWS = ((6, 11), (15, 20))


def marker_video(n_frames, *, occluded=False):
    """Gray 128 with a bright Gaussian marker at ANCHOR; the occluder in WINDOWS if asked."""
    y, x = np.mgrid[0 : SHAPE[0], 0 : SHAPE[1]]
    base = 128 + 120 * np.exp(-((x - ANCHOR[0]) ** 2 + (y - ANCHOR[1]) ** 2) / (2 * 6.0**2))
    frames = np.repeat(base[None], n_frames, axis=0).astype(np.float32)
    if occluded:
        x0, y0, x1, y1 = OCCLUDER
        for t0, t1 in WINDOWS:
            frames[t0:t1, y0:y1, x0:x1] = 0
    return frames


def truth(points, t):
    return ANCHOR + np.exp(LOG_STRETCH * t) * (points - ANCHOR)


def standin(**kwargs):
    predictor = StandInPredictor(**kwargs)
    with torch.no_grad():
        predictor.model.log_stretch.copy_(torch.from_numpy(LOG_STRETCH))
    return predictor


def points():
    return make_grid(SHAPE, shape=(5, 5), roi=ROI)


def run(frames, predictor, **options):
    return track_cotracker(frames, points(), predictor=predictor, value_range=(0, 255), **options)


def path_error(tracks):
    expected = np.stack([truth(points(), t) for t in range(tracks.n_frames)])
    return np.abs(tracks.positions - expected).max()


def test_crop_box_adds_the_margin_and_the_model_aspect_inside_the_frame():
    box = crop_box(np.array([[100.0, 100.0], [199.0, 199.0]]), (800, 800), margin=0.5)
    assert box == (17, 50, 283, 250)  # 198 px + margins -> 4:3, i.e. 264 x 198 px
    assert crop_box(np.array([[5.0, 5.0], [60.0, 40.0]]), (100, 200), margin=1.0)[:2] == (0, 0)
    x0, y0, x1, y1 = crop_box(np.array([[0.0, 0.0], [300.0, 300.0]]), (400, 400), margin=2.0)
    assert (x0, y0, x1, y1) == (0, 0, 400, 400)
    with pytest.raises(InputError, match="crop-margin"):
        crop_box(np.zeros((3, 2)), (10, 10), margin=-1)


@pytest.mark.parametrize("crop", [True, False])
def test_points_follow_the_video_with_and_without_the_crop(crop):
    predictor = standin()
    tracks = run(marker_video(12), predictor, crop=crop)
    (call,) = predictor.calls
    x0, y0, x1, y1 = tracks.meta["options"]["crop_box_px"]
    if crop:  # the model saw the region only, at a higher resolution
        assert (x0, y0, x1, y1) == crop_box(points(), SHAPE, margin=0.5) == (43, 30, 258, 191)
        assert (call["W"], call["H"]) == (x1 - x0, y1 - y0)
        assert tracks.meta["options"]["model_pixels_per_px"][0] > 2.3
    else:
        assert (x0, y0, x1, y1) == (0, 0, 320, 240) and (call["W"], call["H"]) == (320, 240)
        assert tracks.meta["options"]["model_pixels_per_px"][0] < 1.61
    # a crop offset missed or a scale misapplied would be tens of pixels off
    assert path_error(tracks) < COTRACKER_STANDIN_PX
    assert tracks.visible.all() and (tracks.quality == 1).all()
    np.testing.assert_array_equal(tracks.positions[0], points())


def test_long_videos_run_in_overlapping_chunks_requeried_where_points_were_last_seen():
    frames = marker_video(23, occluded=True)
    predictor = standin(window_len=8)  # refuses more than 8 frames
    done = []
    tracks = run(
        frames,
        predictor,
        chunk_frames=8,
        chunk_overlap=3,
        progress=lambda k, n: done.append((k, n)),
    )
    assert [c["T"] for c in predictor.calls] == [8, 8, 8, 8]  # [0,8) [5,13) [10,18) [15,23)
    assert done == [(8, 23), (13, 23), (18, 23), (23, 23)]
    assert tracks.meta["options"]["time_chunks"] == 4
    assert path_error(tracks) < COTRACKER_STANDIN_PX

    # occluded points: those under the black region during its windows (2 px clear of its edge)
    x0, y0, x1, y1 = OCCLUDER
    expected = np.stack([truth(points(), t) for t in range(23)])
    inside = np.minimum.reduce(
        [expected[..., 0] - x0, x1 - expected[..., 0], expected[..., 1] - y0, y1 - expected[..., 1]]
    )
    in_window = np.zeros(23, dtype=bool)
    for t0, t1 in WINDOWS:
        in_window[t0:t1] = True
    hidden = (inside > 2) & in_window[:, None]
    shown = (inside < -2) | ~in_window[:, None]
    assert hidden.sum() == 2 * 10 and shown.sum() > 0.9 * hidden.size
    assert not tracks.visible[hidden].any() and tracks.visible[shown].all()
    np.testing.assert_array_equal(tracks.quality, tracks.visible.astype(float))

    # chunk 2 starts at frame 5; the occluded points were last seen on frame 5, the others on 7
    hidden_points = hidden.any(axis=0)
    query_t = np.array(predictor.calls[1]["query_t"])
    assert set(query_t[hidden_points]) == {0} and set(query_t[~hidden_points]) == {2}

    # the same result as in one call
    one = run(frames, standin(), chunk_frames=60)
    np.testing.assert_allclose(tracks.positions, one.positions, atol=1e-3)
    np.testing.assert_array_equal(tracks.visible, one.visible)


def test_many_points_run_in_query_chunks():
    predictor = standin()
    chunked = run(marker_video(9, occluded=True), predictor, query_chunk=7)
    assert [c["N"] for c in predictor.calls] == [7, 7, 7, 4]
    assert chunked.meta["options"]["model_calls"] == 4
    whole = run(marker_video(9, occluded=True), standin())
    np.testing.assert_allclose(chunked.positions, whole.positions, atol=1e-9)
    np.testing.assert_array_equal(chunked.visible, whole.visible)


@pytest.mark.parametrize("mode", ["bool", "prob", "conf"])
def test_visibility_and_confidence_become_visible_and_quality(mode):
    tracks = run(marker_video(9, occluded=True), standin(mode=mode))
    hidden = ~tracks.visible
    assert hidden[6:9].sum() == 2 * 3 and not hidden[:6].any()
    expected = {"bool": 1.0, "prob": 1.0, "conf": 0.9}[mode]
    np.testing.assert_allclose(tracks.quality[1:][tracks.visible[1:]], expected)  # 0: reference
    assert (tracks.quality[hidden] < 0.5).all()


def test_intensities_are_scaled_to_0_255_and_gray_is_replicated():
    """12-bit frames with their range: the stand-in refuses anything but 0-255 in 3 equal
    channels, and finds its marker only if 128 stays 128."""
    frames = marker_video(6) * 16
    tracks = track_cotracker(frames, points(), predictor=standin(), value_range=(0, 4080))
    assert path_error(tracks) < COTRACKER_STANDIN_PX
    assert tracks.meta["options"]["value_range"] == [0.0, 4080.0]


def test_device_defaults_to_cuda_when_present_with_optional_half_precision(monkeypatch):
    """On a GPU machine this runs the model on CUDA under float16 autocast; on a CPU
    machine it checks the CPU default (the CUDA choice itself is checked below)."""
    predictor = standin()
    cuda = torch.cuda.is_available()
    tracks = run(marker_video(8), predictor, half=cuda)
    call = predictor.calls[-1]
    assert call["device"] == call["param_device"] == ("cuda" if cuda else "cpu")
    assert call["probe_dtype"] == (torch.float16 if cuda else torch.float32)
    assert tracks.meta["options"]["dtype"] == ("float16 (autocast)" if cuda else "float32")
    assert tracks.positions.dtype == np.float64
    assert path_error(tracks) < COTRACKER_STANDIN_PX

    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 1)
    assert _device(torch, None, False).type == "cuda"
    assert _device(torch, "cpu", False).type == "cpu"
    with pytest.raises(InputError, match="only 1 CUDA"):
        _device(torch, "cuda:3", False)
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    assert _device(torch, None, False).type == "cpu"
    with pytest.raises(InputError, match="sees no CUDA device"):
        _device(torch, "cuda", False)
    with pytest.raises(InputError, match="--half"):
        _device(torch, None, True)
    for bad in ("gpu", "mps"):
        with pytest.raises(InputError, match="--device must be"):
            _device(torch, bad, False)


@pytest.mark.parametrize(
    "options, message",
    [
        ({"chunk_frames": 1}, "--chunk-frames"),
        ({"chunk_frames": 8, "chunk_overlap": 8}, "--chunk-overlap"),
        ({"chunk_overlap": 0}, "--chunk-overlap"),
        ({"query_chunk": 0}, "--query-chunk"),
        ({"crop_margin": float("nan")}, "--crop-margin"),
    ],
)
def test_bad_options_are_named(options, message):
    with pytest.raises(InputError, match=message):
        run(marker_video(3), standin(), **options)


def test_registered_without_importing_torch_and_left_out_of_the_default_benchmark():
    code = (
        "import sys, strain2d; spec = strain2d.available_trackers()['cotracker3']; "
        "print(spec.needs_frames, spec.needs_model, 'torch' in sys.modules)"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert res.stdout.split() == ["True", "True", "False"]


# -- where the model comes from ----------------------------------------------------------


@pytest.fixture
def hub_repo(tmp_path):
    """A local torch.hub repository shaped like the official one, serving the stand-in."""
    repo = tmp_path / "co-tracker"
    repo.mkdir()
    shutil.copy(cotracker_standin.__file__, repo / "fake_cotracker_standin.py")
    (repo / "hubconf.py").write_text(
        "dependencies = ['torch']\n"
        "from fake_cotracker_standin import StandInPredictor\n\n\n"
        "def cotracker3_offline(*, pretrained=True, **kwargs):\n"
        "    if pretrained:\n"
        "        raise RuntimeError('no network here\\nsecond line')\n"
        "    return StandInPredictor(**kwargs)\n"
    )
    return repo


@pytest.fixture
def checkpoint(tmp_path):
    path = tmp_path / "scaled_offline.pth"
    torch.save(standin().model.state_dict(), path)
    return path


def test_repository_and_checkpoint_load_the_weights(monkeypatch, tmp_path, hub_repo, checkpoint):
    monkeypatch.setenv("HOME", str(tmp_path))  # paths from Python may start with ~
    predictor = load_cotracker3(repo="~/co-tracker", checkpoint="~/scaled_offline.pth")
    assert type(predictor).__name__ == "StandInPredictor"
    np.testing.assert_allclose(predictor.model.log_stretch.detach().numpy(), LOG_STRETCH)
    tracks = track_cotracker(
        marker_video(6), points(), repo=hub_repo, checkpoint=checkpoint, value_range=(0, 255)
    )
    assert path_error(tracks) < COTRACKER_STANDIN_PX
    options = tracks.meta["options"]
    assert options["repo"] == str(hub_repo) and options["checkpoint"] == str(checkpoint)
    assert options["model"]["code"] == "repository"
    assert options["model_input_size"] == [384, 512]


def test_download_is_only_asked_for_explicitly(hub_repo, checkpoint):
    with pytest.raises(InputError, match=r"not its weights.*--cotracker-checkpoint"):
        load_cotracker3(repo=hub_repo)
    with pytest.raises(InputError, match="cannot load cotracker3_offline") as err:
        load_cotracker3(repo=hub_repo, download=True)  # pretrained=True reaches the hubconf
    assert "no network here" in str(err.value) and "\n" not in str(err.value)


@pytest.fixture
def no_package(monkeypatch):
    monkeypatch.setitem(sys.modules, "cotracker", None)


@pytest.mark.usefixtures("no_package")
def test_missing_code_or_weights_say_how_to_get_them(tmp_path, hub_repo, checkpoint):
    with pytest.raises(InputError, match=r"clone https://github\.com/facebookresearch/co-tracker"):
        load_cotracker3()
    with pytest.raises(InputError, match="holds the weights only"):
        load_cotracker3(checkpoint=checkpoint)
    with pytest.raises(InputError, match="is not a folder"):
        load_cotracker3(repo=tmp_path / "nope", checkpoint=checkpoint)
    with pytest.raises(InputError, match=r"no hubconf\.py"):
        load_cotracker3(repo=tmp_path, checkpoint=checkpoint)
    with pytest.raises(InputError, match="no such CoTracker3 checkpoint"):
        load_cotracker3(repo=hub_repo, checkpoint=tmp_path / "nope.pth")
    with pytest.raises(InputError, match=r"--cotracker-checkpoint .* is a folder; give the"):
        load_cotracker3(repo=hub_repo, checkpoint=tmp_path)


def test_unusable_checkpoints_are_one_line_errors(tmp_path, hub_repo):
    cases = {
        "junk.pth": (lambda p: p.write_bytes(b"not a checkpoint"), "cannot read the checkpoint"),
        "wrong.pth": (
            lambda p: torch.save({"other.weight": torch.zeros(2)}, p),
            "does not fit the model: weights 3 missing",
        ),
        "shape.pth": (
            lambda p: torch.save(
                {**standin().model.state_dict(), "log_stretch": torch.zeros(3)}, p
            ),
            "does not fit the model: RuntimeError",
        ),
        "pickle.pth": (lambda p: torch.save({"x": Path("a")}, p), "cannot read the checkpoint"),
        "list.pth": (lambda p: torch.save([torch.zeros(1)], p), "holds no state dict"),
    }
    for name, (write, message) in cases.items():
        write(tmp_path / name)
        with pytest.raises(InputError, match=message) as err:
            load_cotracker3(repo=hub_repo, checkpoint=tmp_path / name)
        assert "\n" not in str(err.value), name
    # a training checkpoint that wraps the weights under "model" loads
    torch.save({"model": standin().model.state_dict(), "step": torch.tensor(1)}, tmp_path / "w.pth")
    predictor = load_cotracker3(repo=hub_repo, checkpoint=tmp_path / "w.pth")
    np.testing.assert_allclose(predictor.model.log_stretch.detach().numpy(), LOG_STRETCH)


@pytest.fixture
def installed_package(tmp_path, monkeypatch):
    """A ``cotracker`` package on sys.path whose CoTrackerPredictor is the stand-in."""
    package = tmp_path / "site" / "cotracker"
    package.mkdir(parents=True)
    (package / "__init__.py").write_text("")
    shutil.copy(cotracker_standin.__file__, package / "standin.py")
    (package / "predictor.py").write_text(
        "from cotracker.standin import StandInPredictor\n\n\n"
        "class CoTrackerPredictor(StandInPredictor):\n"
        "    def __init__(self, checkpoint='./checkpoints/x.pth', offline=True, window_len=60,"
        " v2=False):\n"
        "        assert checkpoint is None and offline and not v2\n"
        "        super().__init__(window_len=window_len)\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path / "site"))
    yield
    for name in ("cotracker", "cotracker.predictor", "cotracker.standin"):
        sys.modules.pop(name, None)


@pytest.mark.usefixtures("installed_package")
def test_an_installed_cotracker_package_is_used_with_a_checkpoint(checkpoint):
    with pytest.raises(InputError, match="installed cotracker package gives"):
        load_cotracker3()
    predictor = load_cotracker3(checkpoint=checkpoint)
    assert type(predictor).__name__ == "CoTrackerPredictor" and predictor.window_len == 60
    np.testing.assert_allclose(predictor.model.log_stretch.detach().numpy(), LOG_STRETCH)


def test_without_torch_the_error_names_the_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "torch", None)
    with pytest.raises(InputError, match=r"needs PyTorch: pip install 'tissue-strain\[torch\]'"):
        track(marker_video(3), points(), tracker="cotracker3")


# -- command line ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def video_file(tmp_path_factory):
    from sample_data_synth import make_case, write_video

    folder = tmp_path_factory.mktemp("cotracker")
    video = make_case("equibiaxial", size=128, n_frames=6, rng=0)
    write_video(video.frames, folder / "eq.tif")
    return folder / "eq.tif"


def one_line_error(capsys, argv, expected):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert expected in err and len(err.strip().splitlines()) == 1, err


@pytest.mark.usefixtures("no_package")
def test_cli_paths_without_torch_repository_or_weights_end_in_one_line(
    capsys, monkeypatch, tmp_path, video_file, hub_repo, checkpoint
):
    base = ["-q", "track", str(video_file), "--tracker", "cotracker3", "--grid", "3x3"]
    out = ["--out", str(tmp_path / "t.csv")]
    one_line_error(capsys, [*base, *out], "needs CoTracker3's code and weights")
    one_line_error(capsys, [*base, "--cotracker-repo", str(hub_repo), *out], "not its weights")
    one_line_error(
        capsys,
        [
            *base,
            "--cotracker-repo",
            str(tmp_path / "x"),
            "--cotracker-checkpoint",
            str(checkpoint),
            *out,
        ],
        "is not a folder",
    )
    one_line_error(capsys, [*base, "--cotracker-checkpoint", str(checkpoint), *out], "weights only")
    one_line_error(capsys, [*base, "--chunk-overlap", "0", *out], "--chunk-overlap")
    one_line_error(capsys, [*base, "--device", "tpu", *out], "--device must be")
    one_line_error(
        capsys,
        ["-q", "track", str(video_file), "--device", "cpu", *out],
        "does not apply to the gdic",
    )
    monkeypatch.setitem(sys.modules, "torch", None)
    one_line_error(capsys, [*base, *out], "needs PyTorch")
    assert not (tmp_path / "t.csv").exists()


def test_cli_without_a_model_in_a_fresh_process(tmp_path, video_file):
    res = subprocess.run(
        [
            sys.executable,
            "-m",
            "strain2d",
            "track",
            str(video_file),
            "--tracker",
            "cotracker3",
            "--out",
            str(tmp_path / "t.csv"),
        ],
        capture_output=True,
        text=True,
    )
    assert res.returncode == 2 and len(message_lines(res.stderr)) == 1, res.stderr
    assert "--cotracker-repo" in res.stderr


def test_analyze_and_track_with_repository_and_checkpoint(
    tmp_path, video_file, hub_repo, checkpoint
):
    """The done-when command lines, with the stand-in in place of the official model: the
    strain is the stand-in's stretch, Exx = (1.02**10 - 1)/2 and Eyy = (0.985**10 - 1)/2."""
    model = ["--cotracker-repo", str(hub_repo), "--cotracker-checkpoint", str(checkpoint)]
    common = ["--tracker", "cotracker3", *model, "--chunk-frames", "4", "--chunk-overlap", "2"]
    out = tmp_path / "run"
    res = subprocess.run(
        [
            sys.executable,
            "-m",
            "strain2d",
            "-q",
            "analyze",
            str(video_file),
            "--grid",
            "4x4",
            *common,
            "--out",
            str(out),
        ],
        capture_output=True,
        text=True,
    )
    assert res.returncode == 0, res.stderr
    rows = np.genfromtxt(out / "strain_nodes.csv", delimiter=",", names=True)
    last = rows[rows["frame"] == 5]
    np.testing.assert_allclose(last["Exx"], (1.02**10 - 1) / 2, atol=1e-5)
    np.testing.assert_allclose(last["Eyy"], (0.985**10 - 1) / 2, atol=1e-5)
    np.testing.assert_allclose(last["Exy"], 0, atol=1e-5)
    tracker = json.loads((out / "summary.json").read_text())["tracker"]
    options = tracker["options"]
    assert tracker["name"] == "cotracker3"
    assert options["repo"] == str(hub_repo) and options["checkpoint"] == str(checkpoint)
    assert options["device"] == ("cuda" if torch.cuda.is_available() else "cpu")
    assert options["dtype"] == "float32" and options["crop"] is True
    assert options["model_input_size"] == [384, 512]
    assert (options["chunk_frames"], options["chunk_overlap"], options["time_chunks"]) == (4, 2, 2)

    csv = tmp_path / "tracks.csv"
    assert main(["-q", "track", str(video_file), "--grid", "4x4", *common, "--out", str(csv)]) == 0
    tracks = np.genfromtxt(csv, delimiter=",", names=True)
    np.testing.assert_allclose(tracks["x"], rows["x"], atol=1e-5)


def test_a_chunk_of_frames_beyond_the_memory_is_refused_before_the_model_runs(monkeypatch):
    import tissue_core.resources as resources

    monkeypatch.setattr(resources, "available_memory", lambda: 4 * 2**20)
    predictor = standin()
    said = r"--chunk-frames 1000000 \(9 frames of 320x240 px in each model call\) needs 5.27 MiB"
    with pytest.raises(InputError, match=said):
        run(marker_video(9), predictor, chunk_frames=1000000, crop=False)
    assert predictor.calls == []
    run(marker_video(9), predictor, chunk_frames=1000000)  # the crop around the points fits
