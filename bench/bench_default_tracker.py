"""The default tracker against dic and klt: speed, threads, variants, rotation, still, real.

Prints one Markdown table per part (``--only`` picks parts, ``--trackers``
the trackers; the default tracker is compared with ``dic``):

speed
    Time (one run, after a warm-up that compiles the kernels) and
    point-frames per second of every tracker on the full-HD twitching muscle
    sheet (:mod:`sample_data_synth.sheet`: 1920 x 1080, 41 frames, 29 x 15
    points), the tissue suite's weak-texture cases (closeup-gaussian,
    vessels-contraction, fur-gaussian, retina-contraction; 800 px, 21
    frames) and the dense speckle grid (equibiaxial, 800 px, 31 frames,
    50 x 50 points); each time over dic's, points kept, final-frame RMSE and
    RMSE over all frames (px).
threads
    Each tracker on the dense speckle grid in a fresh process on 1 and on 2
    CPU cores, or the counts ``--thread-counts`` names (affinity,
    ``NUMBA_NUM_THREADS`` and ``OMP_NUM_THREADS``, and the tracker's
    ``threads`` option where it has one): the speed-ups, the point-frames per
    second at the largest count, and whether the tracks are identical.
variants
    The randomised variants of the tissue suite (:mod:`sample_data_synth.variants`):
    per variant dic's and the default's final-frame RMSE and points kept, the
    default's RMSE on the points dic keeps (the same points for both), and
    the verdict of :func:`sample_data_synth.measures.compare_to_dic` (within
    10 % of dic or better where dic keeps its points; keeps them where dic
    loses some); a summary line.
rotation
    Textured pieces on a blank background turned 20 degrees per frame
    (:mod:`sample_data_synth.pieces`): RMS error of the 21 textured points
    against the rigid motion, and how many of the 60 blank points were
    reported visible.
still
    Still videos of scikit-image photographs at three noise levels
    (:mod:`sample_data_synth.still`): each tracker's reported sigma against
    its measured scatter (deviation from the unmoving truth), per point.
real
    The cardiomyocyte recordings in ``shared/data/real/cardiomyocyte_sheets``:
    the default's sigma against its disagreement with dic (dic reports no
    sigma, so a calibrated default shows a ratio near 0.7 if both err alike).

    python bench/bench_default_tracker.py [--only speed,threads,variants,rotation,still,real]
        [--trackers gdic,dic,klt] [--variants 32] [--seed 0] [--sheet-frames 41]
        [--real DIR] [--thread-counts 1,2]

Times are wall-clock on a machine that may be shared: compare ratios taken in
the same run.
"""

from __future__ import annotations

import argparse
import inspect
import os
import platform
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # this checkout's packages

PARTS = ("speed", "threads", "variants", "rotation", "still", "real")
WEAK_CASES = ("closeup-gaussian", "vessels-contraction", "fur-gaussian", "retina-contraction")
DEFAULT = "gdic"
#: s: a run shorter than this is repeated (the fastest of the repeats counts)
_REPEAT_UNDER = 15.0


def _run(tracker: str, frames, points, options: dict | None = None):
    """Tracks and seconds; the warnings of points left out are the tables' business."""
    from strain2d import track

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        t0 = time.perf_counter()
        tracks = track(frames, points, tracker=tracker, options=options)
        return tracks, time.perf_counter() - t0


def _warm_up(trackers: list[str]) -> None:
    """Compile every tracker's kernels on a small video so no timing includes it."""
    from sample_data_synth import make_case

    video = make_case("equibiaxial", size=160, n_frames=3, rng=1)
    points = video.truth.grid((5, 5))
    for name in trackers:
        _run(name, video.frames, points)


def _fmt(value: float, digits: int = 3) -> str:
    return "-" if value is None or not np.isfinite(value) else f"{value:.{digits}f}"


# ----------------------------------------------------------------------------- cases


def _speed_cases(sheet_frames: int):
    """(name, frames, points, true positions) of the speed part, rendered one at a time."""
    from sample_data_synth.sheet import SHEET_GRID, make_muscle_sheet
    from sample_data_synth.tissue import make_tissue_case

    video = make_muscle_sheet(n_frames=sheet_frames, rng=0)
    points = video.truth.grid(SHEET_GRID)
    yield "muscle sheet 1920x1080", video.frames, points, video.truth.positions(points)
    for case in WEAK_CASES:
        video = make_tissue_case(case, size=800, rng=0)
        points = video.truth.grid(tuple(video.truth.params["grid"]))
        yield case, video.frames, points, video.truth.positions(points)
    frames, points, true = _dense_speckle()
    yield "speckle 50x50 (equibiaxial)", frames, points, true


def _dense_speckle():
    from sample_data_synth import make_case

    video = make_case("equibiaxial", size=800, n_frames=31, rng=0)
    points = video.truth.grid((50, 50))
    return video.frames, points, video.truth.positions(points)


# ----------------------------------------------------------------------------- parts


def part_speed(trackers: list[str], sheet_frames: int, repeats: int = 3) -> None:
    from sample_data_synth.measures import score_tracks

    print("## Speed\n")
    print(
        f"Each tracker run up to {repeats} times per case, the trackers alternating; the "
        f"fastest run counts (a tracker whose run took over {_REPEAT_UNDER:.0f} s runs once: "
        "the machine's noise is small beside it).\n"
    )
    print(
        "| case | points x frames | tracker | time (s) | point-frames/s | time / dic | kept | "
        "final RMSE (px) | RMSE all frames (px) |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for case, frames, points, true in _speed_cases(sheet_frames):
        seconds, scores = {}, {}
        for k in range(repeats):
            for name in trackers:
                if k and seconds[name] > _REPEAT_UNDER:
                    continue
                tracks, took = _run(name, frames, points)
                seconds[name] = min(took, seconds.get(name, np.inf))
                scores[name] = score_tracks(
                    tracks.positions, tracks.visible, true, shape=frames.shape[1:]
                )
        n = len(points) * len(frames)
        for name in trackers:
            ratio = seconds[name] / seconds["dic"] if "dic" in seconds else float("nan")
            score = scores[name]
            print(
                f"| {case} | {len(points)} x {len(frames)} | {name} | {seconds[name]:.1f} | "
                f"{n / seconds[name]:,.0f} | {_fmt(ratio, 2)} | {score.kept}/{score.in_view} | "
                f"{_fmt(score.rmse)} | {_fmt(score.rmse_all)} |",
                flush=True,
            )
    print()


def _thread_worker(tracker: str, cores: int, source: str, target: str) -> None:
    """One tracker on the saved dense speckle case, on ``cores`` CPU cores."""
    if hasattr(os, "sched_setaffinity"):
        allowed = sorted(os.sched_getaffinity(0))
        os.sched_setaffinity(0, allowed[:cores])
    from strain2d import get_tracker

    data = np.load(source)
    frames, points = data["frames"], data["points"]
    accepts = inspect.signature(get_tracker(tracker).function).parameters
    options = {"threads": cores} if "threads" in accepts else None
    _run(tracker, frames[:3], points[::37], options)  # compile, outside the timing
    tracks, seconds = _run(tracker, frames, points, options)
    np.savez(target, positions=tracks.positions, visible=tracks.visible, seconds=seconds)


def part_threads(trackers: list[str], repeats: int = 3, counts: tuple[int, ...] = (1, 2)) -> None:
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    counts = tuple(n for n in counts if n <= cores)
    words = " against ".join(f"{n} thread{'s' * (n > 1)}" for n in counts)
    print(f"## {words.capitalize()} (dense speckle, 50x50 points x 31 frames)\n")
    print(
        f"Each count run {repeats} times, alternating, each in a fresh process; the fastest "
        "run of each counts (this machine is shared: the slower runs measure the others).\n"
    )
    if len(counts) < 2:
        print(f"only {cores} CPU core available: no speed-up to measure\n")
        return
    frames, points, _ = _dense_speckle()
    point_frames = len(points) * len(frames)
    head = " | ".join(f"{n} thr. (s)" for n in counts)
    ups = " | ".join(f"{n}/1" for n in counts[1:])
    print(f"| tracker | {head} | {ups} | point-frames/s at {counts[-1]} | identical tracks |")
    print("|---|" + "---|" * (2 * len(counts) + 1))
    with tempfile.TemporaryDirectory() as folder:
        source = Path(folder) / "speckle.npz"
        np.savez(source, frames=frames, points=points)
        for name in trackers:
            result, best = {}, dict.fromkeys(counts, np.inf)
            for _ in range(repeats):
                for n in counts:
                    target = Path(folder) / f"{name}_{n}.npz"
                    env = dict(os.environ, NUMBA_NUM_THREADS=str(n), OMP_NUM_THREADS=str(n))
                    env.update(OPENBLAS_NUM_THREADS=str(n), MKL_NUM_THREADS=str(n))
                    command = [sys.executable, __file__, "--thread-worker", name, str(n)]
                    subprocess.run([*command, str(source), str(target)], env=env, check=True)
                    result[n] = dict(np.load(target))
                    best[n] = min(best[n], float(result[n]["seconds"]))
            a = result[counts[0]]
            gap = max(
                float(np.nanmax(np.abs(a["positions"] - result[n]["positions"]), initial=0.0))
                for n in counts[1:]
            )
            same = all(
                np.array_equal(a["positions"], result[n]["positions"], equal_nan=True)
                and np.array_equal(a["visible"], result[n]["visible"])
                for n in counts[1:]
            )
            same_text = "yes" if same else f"no (largest difference {gap:.2e} px)"
            times = " | ".join(f"{best[n]:.1f}" for n in counts)
            speedups = " | ".join(f"{best[counts[0]] / best[n]:.2f}" for n in counts[1:])
            rate = point_frames / best[counts[-1]]
            print(f"| {name} | {times} | {speedups} | {rate:,.0f} | {same_text} |", flush=True)
    print()


def part_variants(trackers: list[str], n: int, seed: int) -> None:
    from sample_data_synth.measures import compare_to_dic, score_tracks
    from sample_data_synth.variants import make_variant, tissue_variants

    print(f"## Randomised variants of the tissue suite ({n}, seed {seed})\n")
    others = [name for name in trackers if name not in ("dic", DEFAULT)]
    pair = [name for name in ("dic", DEFAULT) if name in trackers]
    if pair != ["dic", DEFAULT]:
        print(f"the variants compare {DEFAULT} with dic: name both in --trackers\n")
        return
    extra = "".join(f" {name} RMSE / kept |" for name in others)
    print(
        f"| variant | what | dic RMSE (px) | dic kept | {DEFAULT} RMSE (px) | {DEFAULT} kept | "
        f"ratio | {DEFAULT} on dic's points (px) | ratio there | verdict | dic (s) | "
        f"{DEFAULT} (s) |{extra}"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|" + "---|" * len(others))
    verdicts = []
    for variant in tissue_variants(n, rng=seed):
        video = make_variant(variant)
        points = video.truth.grid(variant.grid)
        true = video.truth.positions(points)
        scores, seconds, tracks = {}, {}, {}
        for name in pair + others:
            tracks[name], seconds[name] = _run(name, video.frames, points)
            scores[name] = score_tracks(tracks[name].positions, tracks[name].visible, true)
        result = compare_to_dic(scores[DEFAULT], scores["dic"])
        verdicts.append((scores["dic"].keeps_all, result))
        d, g = scores["dic"], scores[DEFAULT]
        shared = score_tracks(
            tracks[DEFAULT].positions, tracks[DEFAULT].visible, true, among=d.kept_points
        )
        cells = "".join(
            f" {_fmt(scores[name].rmse)} / {scores[name].kept}/{scores[name].in_view} |"
            for name in others
        )
        print(
            f"| {variant.name} | {variant.describe()} | {_fmt(d.rmse)} | {d.kept}/{d.in_view} | "
            f"{_fmt(g.rmse)} | {g.kept}/{g.in_view} | {_fmt(result.ratio, 2)} | "
            f"{_fmt(shared.rmse)} | {_fmt(shared.rmse / d.rmse, 2)} | "
            f"{result.verdict} | {seconds['dic']:.1f} | {seconds[DEFAULT]:.1f} |{cells}",
            flush=True,
        )
    kept = [r for dic_keeps, r in verdicts if dic_keeps]
    lost = [r for dic_keeps, r in verdicts if not dic_keeps]
    print(
        f"\n{DEFAULT} within 10 % of dic or better on {sum(r.passed for r in kept)} of "
        f"{len(kept)} variants where dic keeps every point; keeps every point on "
        f"{sum(r.passed for r in lost)} of {len(lost)} where dic loses some; "
        f"{sum(r.passed for _, r in verdicts)} of {len(verdicts)} pass.\n"
    )


def part_rotation(trackers: list[str]) -> None:
    from sample_data_synth.measures import rigid_score
    from sample_data_synth.pieces import PIECES_GRID, make_rotation_pieces

    print("## Textured pieces on a blank background, turned 20 degrees per frame\n")
    video = make_rotation_pieces(rng=0)
    points = video.truth.grid(PIECES_GRID)
    true = video.truth.positions(points)
    on = np.array(video.truth.params["on_texture"])
    print(
        f"{video.frames.shape[2]}x{video.frames.shape[1]} px, {len(video.frames)} frames; "
        f"{on.sum()} points on texture, {(~on).sum()} on the blank background\n"
    )
    print(
        "| tracker | textured RMS (px) | textured kept | blank points reported visible | "
        "blank point-frames visible | time (s) |"
    )
    print("|---|---|---|---|---|---|")
    for name in trackers:
        tracks, seconds = _run(name, video.frames, points)
        s = rigid_score(tracks.positions, tracks.visible, true, on)
        print(
            f"| {name} | {_fmt(s.textured_rms, 4)} | {s.textured_kept}/{s.textured} | "
            f"{s.blank_measured}/{s.blank} | {s.blank_point_frames} | {seconds:.1f} |",
            flush=True,
        )
    print()


def part_still(trackers: list[str]) -> None:
    from sample_data_synth.measures import sigma_against_scatter
    from sample_data_synth.still import (
        NOISE_LEVELS,
        STILL_GRID,
        STILL_PHOTOGRAPHS,
        make_still_video,
    )

    print("## Still videos: reported sigma against measured scatter (400 px, 21 frames)\n")
    print(
        "| video | tracker | median sigma (px) | median scatter (px) | median ratio | "
        "pooled ratio | points within 1.5x | kept |"
    )
    print("|---|---|---|---|---|---|---|---|")
    for photograph in STILL_PHOTOGRAPHS:
        for noise in NOISE_LEVELS:
            video = make_still_video(photograph, noise=noise, rng=0)
            points = video.truth.grid(STILL_GRID)
            for name in trackers:
                tracks, _ = _run(name, video.frames, points)
                kept = f"{int(tracks.visible.all(axis=0).sum())}/{len(points)}"
                sigma = tracks.uncertainty
                reported = sigma is not None
                check = sigma_against_scatter(
                    tracks.positions,
                    tracks.visible,
                    sigma if reported else np.zeros(tracks.visible.shape),
                    points,
                )
                print(
                    f"| {photograph}, {noise} noise | {name} | "
                    f"{_fmt(np.nanmedian(check.sigma), 4) if reported else '-'} | "
                    f"{_fmt(np.nanmedian(check.scatter), 4)} | "
                    f"{_fmt(check.median_ratio, 2) if reported else '-'} | "
                    f"{_fmt(check.pooled_ratio, 2) if reported else '-'} | "
                    f"{f'{check.within(1.5):.0%}' if reported else '-'} | {kept} |",
                    flush=True,
                )
    print()


def _real_folder() -> Path | None:
    """``shared/data/real/cardiomyocyte_sheets`` beside the checkout or a folder above it."""
    here = Path(__file__).resolve().parents[1]
    for folder in [here, *here.parents]:
        candidate = folder / "shared" / "data" / "real" / "cardiomyocyte_sheets"
        if candidate.is_dir():
            return candidate
    return None


def part_real(trackers: list[str], folder: Path | None) -> None:
    from sample_data_synth.measures import sigma_against_scatter
    from strain2d import make_grid, open_frames
    from strain2d.pipeline import blank_start

    print(f"## Real recordings: {DEFAULT}'s sigma against its disagreement with dic\n")
    if folder is None or not folder.is_dir():
        print("no cardiomyocyte recordings found (--real DIR)\n")
        return
    if not {"dic", DEFAULT} <= set(trackers):
        print(f"compares {DEFAULT} with dic: name both in --trackers\n")
        return
    print(
        f"| video | from frame | points x frames | {DEFAULT} visible | dic visible | "
        f"RMS {DEFAULT} sigma (px) | RMS disagreement per coordinate (px) | median ratio | "
        f"pooled ratio | {DEFAULT} (s) | dic (s) |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for path in sorted(folder.glob("*.mp4")):
        frames = np.stack([np.asarray(f, dtype=float) for f in open_frames(path)])
        points = make_grid(frames.shape[1:], shape=(9, 9))
        blank = blank_start(frames, points)  # a recording that fades in: from its texture on
        start = 0 if blank is None else blank[0]
        frames = frames[start:]
        tracks, seconds = {}, {}
        for name in (DEFAULT, "dic"):
            tracks[name], seconds[name] = _run(name, frames, points)
        g, d = tracks[DEFAULT], tracks["dic"]
        check = sigma_against_scatter(
            g.positions, g.visible, g.uncertainty, d.positions, reference_visible=d.visible
        )
        w = check.samples
        ok = np.isfinite(check.sigma) & (w > 0)
        rms_sigma = (
            np.sqrt(np.sum(w[ok] * check.sigma[ok] ** 2) / w[ok].sum()) if ok.any() else np.nan
        )
        rms_gap = (
            np.sqrt(np.sum(w[ok] * check.scatter[ok] ** 2) / w[ok].sum()) if ok.any() else np.nan
        )
        print(
            f"| {path.name} | {start} | {len(points)} x {len(frames)} | "
            f"{g.visible[1:].mean():.0%} | "
            f"{d.visible[1:].mean():.0%} | {_fmt(rms_sigma, 4)} | {_fmt(rms_gap, 4)} | "
            f"{_fmt(check.median_ratio, 2)} | {_fmt(check.pooled_ratio, 2)} | "
            f"{seconds[DEFAULT]:.1f} | {seconds['dic']:.1f} |",
            flush=True,
        )
    print(
        "\nvisible: point-frames after the reference; the ratios are sigma over the "
        "disagreement, over the point-frames both trackers report; from frame: the first "
        "textured frame of a recording that fades in (strain2d.pipeline.blank_start)\n"
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--only", default=",".join(PARTS), help=f"parts: {', '.join(PARTS)}")
    parser.add_argument("--trackers", default="gdic,dic,klt")
    parser.add_argument("--variants", type=int, default=32, help="number of variants (32)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the variants (0)")
    parser.add_argument("--sheet-frames", type=int, default=41, help="muscle sheet frames (41)")
    parser.add_argument("--real", type=Path, default=None, help="cardiomyocyte recordings")
    parser.add_argument(
        "--repeats", type=int, default=3, help="runs of each timing; the fastest counts (3)"
    )
    parser.add_argument(
        "--thread-counts", default="1,2", help="thread counts of the threads part (1,2)"
    )
    parser.add_argument("--thread-worker", nargs=4, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.thread_worker:
        tracker, cores, source, target = args.thread_worker
        _thread_worker(tracker, int(cores), source, target)
        return 0
    parts = args.only.split(",")
    unknown = sorted(set(parts) - set(PARTS))
    if unknown:
        parser.error(f"unknown parts {', '.join(unknown)}; choose from {', '.join(PARTS)}")
    trackers = args.trackers.split(",")
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    from tissue_core.version import __version__

    print(
        f"{platform.processor() or platform.machine()}, {cores} cores, Python "
        f"{platform.python_version()}, tissue-strain {__version__}; trackers {', '.join(trackers)}"
        f" (default {DEFAULT})\n"
    )
    _warm_up(trackers)
    if "speed" in parts:
        part_speed(trackers, args.sheet_frames, max(args.repeats, 1))
    if "threads" in parts:
        counts = tuple(int(n) for n in args.thread_counts.split(","))
        part_threads(trackers, max(args.repeats, 1), counts)
    if "variants" in parts:
        part_variants(trackers, args.variants, args.seed)
    if "rotation" in parts:
        part_rotation(trackers)
    if "still" in parts:
        part_still(trackers)
    if "real" in parts:
        part_real(trackers, args.real or _real_folder())
    return 0


if __name__ == "__main__":
    sys.exit(main())
