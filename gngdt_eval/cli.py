"""Evaluate: the paper's tables reproduced, a recording scored against references, a logged run.

``gngdt eval paper`` runs the paper's simulation experiment (Tables 2-4, Figures 8-11);
``gngdt eval recording`` replays a recording offline through each method; ``gngdt eval rrd``
reads a logged run back from its .rrd file. Each writes a Markdown report, a JSON file with every
figure and PNG plots into ``--out``.
"""

from __future__ import annotations

import argparse
import importlib.util
import logging
import sys
from pathlib import Path

from gngdt.eval.paper_common import METHOD_NAMES, METHODS, STOP_RULES, PaperSettings
from gngdt.io.deproject import RUN_POINT_CAP

log = logging.getLogger(__name__)

EXAMPLES = """examples:
  gngdt eval paper --trials 5 --out report/paper      # Tables 2-4, Figures 8-11
  gngdt eval paper --trials 1 --max-nodes 60          # a quick look
  gngdt eval paper --frames ../shared/data/rgbd/*/ ../shared/data/labelled/*/   # + Tables 5-6
  gngdt eval paper --trials 10 --color-noise 0 1 2 3 4 5 6 8 10 15 20 30   # the colour fit
  gngdt eval paper --stop steps --steps 150000        # learn on past the node budget
  gngdt eval recording recordings/tabletop_small.mcap --out report/tabletop
  gngdt eval recording recordings/data2.mcap --method gngdt --trials 3
  gngdt eval recording vanish.mcap --method gngdt --utility-k 0 --replay-share 0  # the paper's
  gngdt eval rrd runs/tabletop-20260101-120000.rrd --out report/run
  gngdt eval segmentation ../shared/data/labelled/mosd_learn --out report/mosd
  gngdt eval segmentation ../shared/data/labelled/ycbv_0000 --independent --online
"""

METHOD_CHOICES = tuple(METHOD_NAMES)  # command-line method names: gngdt, gng, gngw


def _positive_int(text: str) -> int:
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be >= 1, got {value}")
    return value


def _positive_float(text: str) -> float:
    value = float(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {value}")
    return value


def _non_negative_float(text: str) -> float:
    value = float(text)
    if not value >= 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {value}")
    return value


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Register ``paper``, ``recording``, ``rrd`` and ``segmentation`` sub-subcommands."""
    sub = parser.add_subparsers(dest="eval_command", required=True, metavar="WHAT")
    _add_paper(sub)
    _add_recording(sub)
    _add_rrd(sub)
    _add_segmentation(sub)


def _leaf(sub: argparse._SubParsersAction, name: str, help_text: str, description: str,
          examples: str) -> argparse.ArgumentParser:
    """The parser of one ``gngdt eval`` subcommand: help line, description, examples."""
    return sub.add_parser(name, help=help_text, description=description,
                          epilog="examples:\n" + examples,
                          formatter_class=argparse.RawDescriptionHelpFormatter)


def _add_method_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--method", dest="methods", nargs="+", choices=METHOD_CHOICES,
                        default=list(METHOD_CHOICES), help="methods (default: all three)")


def _add_no_progress_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")


def _add_paper(sub: argparse._SubParsersAction) -> None:
    """``gngdt eval paper``: the options of `PaperSettings`, defaults from it."""
    defaults = PaperSettings(workers=1)
    paper = _leaf(
        sub, "paper",
        "the paper's simulation (Tables 2-4, Figures 8-11) and RGB-D (Tables 5-6) runs",
        "Run the paper's simulation experiment (Section 3.1): GNG, GNG-W and GNG-DT on Data1 "
        "and Data2 at every scale and every --color-noise level, over --trials seeds each, each "
        "run stopping at the node budget; with --frames also its RGB-D experiment (Section 3.3) "
        "on real frames. Writes into --out paper.md (Tables 2-6, Figures 8-11, the paper's "
        "claims checked), paper.json (every figure) and the drawings of Figures 8-10 "
        "(figure8_data1.png, figure9_data2.png, figure10_data1.png, figure10_data2.png).",
        "\n".join(line for line in EXAMPLES.splitlines() if " paper " in line) + "\n")
    paper.add_argument("--trials", type=_positive_int, default=defaults.trials,
                       help="trials per cell (default: %(default)s)")
    paper.add_argument("--out", type=Path, default=Path("report/paper"),
                       help="output folder (default: %(default)s)")
    paper.add_argument("--stop", choices=STOP_RULES, default=defaults.stop,
                       help="budget: a run ends when it has --max-nodes nodes (the paper's Step "
                       "10); steps: after exactly --steps steps (default: %(default)s)")
    paper.add_argument("--steps", type=_positive_int, default=defaults.steps,
                       help="learning steps per run with --stop steps (default: %(default)s)")
    paper.add_argument("--max-nodes", type=_positive_int, default=defaults.max_nodes,
                       help="node budget per run (default: %(default)s)")
    paper.add_argument(
        "--color-noise", type=_non_negative_float, nargs="+",
        default=list(defaults.color_noise), metavar="SIGMA",
        help="within-region colour noise levels, std per RGB channel on 0-255; the first is the "
        "main one, the others are reported beside it; 0 = flat colours (default: %(default)s)")
    paper.add_argument(
        "--frames", type=Path, nargs="+", default=[], metavar="DIR",
        help="real RGB-D image folders (TUM, PCL TIFF or colour/depth layout) for the paper's "
        "Tables 5-6; the first frame of each (default: none)")
    paper.add_argument("--all-frames", action="store_true",
                       help="every frame of each --frames folder")
    paper.add_argument("--frame-trials", type=_positive_int, default=None,
                       help="trials per real frame and method (default: --trials)")
    paper.add_argument("--data1-points", type=_positive_int, default=defaults.data1_points,
                       help="points in Data1 (default: %(default)s, as in the paper)")
    paper.add_argument("--data2-points", type=_positive_int, default=defaults.data2_points,
                       help="points in Data2 (default: %(default)s, as in the paper)")
    paper.add_argument("--scales", type=_positive_float, nargs="+",
                       default=list(defaults.scales), metavar="SCL",
                       help="scale factors scl (default: 1 10 0.1 0.01)")
    paper.add_argument("--datasets", nargs="+", choices=["Data1", "Data2"],
                       default=["Data1", "Data2"], help="data sets (default: both)")
    _add_method_option(paper)
    paper.add_argument("--min-cluster-size", type=_positive_int,
                       default=defaults.min_cluster_size,
                       help="clusters with fewer nodes are not counted (default: %(default)s)")
    paper.add_argument("--workers", type=_positive_int, default=None,
                       help="worker processes (default: one per core)")
    _add_no_progress_option(paper)


def _add_recording(sub: argparse._SubParsersAction) -> None:
    """``gngdt eval recording``: the options of `RecordingSettings` (default None: the
    learner's)."""
    recording = _leaf(
        sub, "recording", "replay a recording offline through each method",
        "Replay a recording offline, frame after frame, through each method as the learner "
        "would (no zenoh). Every frame: quantization errors (eq. 17), nodes, clusters per "
        "topology and, where the recording has ground-truth labels, the adjusted Rand index; on "
        "the last frame, k-means, a voxel grid and DBSCAN as references. Writes recording.md, "
        "recording.json and plots into --out.",
        "  gngdt eval recording recordings/tabletop_small.mcap --out report/tabletop\n"
        "  gngdt eval recording recordings/data2.mcap --method gngdt --trials 3\n"
        "  gngdt eval recording mybag_0.mcap --max-frames 100 --samples-per-frame 20000\n")
    recording.add_argument("path", type=Path, metavar="PATH", help="MCAP recording")
    _add_method_option(recording)
    recording.add_argument("--trials", type=_positive_int, default=1,
                           help="seeds per method (default: %(default)s)")
    recording.add_argument("--out", type=Path, default=None,
                           help="output folder (default: report/<recording name>)")
    recording.add_argument("--samples-per-frame", type=_positive_int, default=None,
                           help="learning steps per frame (default: the learner's)")
    recording.add_argument("--max-nodes", type=_positive_int, default=None,
                           help="node budget (default: the learner's: GNGDT's 1000 for a "
                           "camera-frame map; with camera poses the map grows with the "
                           "surface seen, one node per 0.1 m cell, up to 20,000)")
    recording.add_argument("--max-frames", type=_positive_int, default=None,
                           help="stop after this many frames")
    recording.add_argument(
        "--max-points", type=int, default=None, metavar="N",
        help="each frame's cloud: a random subset of at most N points, drawn as `gngdt run` "
        f"draws it, so both learn the same clouds (default {RUN_POINT_CAP:,}; 0: every point)")
    recording.add_argument(
        "--min-cluster-size", type=_positive_int, default=None,
        help="clusters with fewer nodes are not counted (default: the learner's)")
    recording.add_argument(
        "--object-confirm-frames", type=_positive_int, default=None,
        help="a cluster is an object once seen in this many frames in a row (object identity "
        "scores; default: the learner's)")
    recording.add_argument(
        "--reference-points", type=_positive_int, default=20_000,
        help="last-frame points used to fit k-means and run DBSCAN (default: %(default)s)")
    recording.add_argument(
        "--dbscan-eps", type=_positive_float, default=None,
        help="DBSCAN radius in metres (default: 1.5 x median distance to the 10th neighbour)")
    recording.add_argument(
        "--utility-k", type=float, default=None,
        help="GNG-DT's forgetting threshold (default: the learner's profile; 0: off, the paper)")
    recording.add_argument(
        "--replay-share", type=float, default=None,
        help="GNG-DT's share of each frame's steps rehearsed from earlier frames (default: the "
        "learner's profile; 0: off, the paper)")
    recording.add_argument("--camera-frame", action="store_true",
                           help="ignore the recording's camera poses: learn in the camera frame")
    recording.add_argument("--settle", action="store_true",
                           help="GNG-DT: after the last frame, learn it on until settled as `gngdt "
                           "run` does at a stream's end (a last row, marked settled); without "
                           "it every row is a frame as learned, so a short recording ends with "
                           "fewer nodes than `gngdt run` shows")
    recording.add_argument(
        "--ghost-distance", type=_positive_float, default=0.05,
        help="a seen node farther than this (metres) from the frame is a ghost (default 0.05)")
    recording.add_argument(
        "--world-sample", type=_positive_int, default=40_000,
        help="with poses, points kept of the world seen so far (k-means is fitted on half, "
        "both errors measured on the other half; default %(default)s)")
    recording.add_argument(
        "--reference-every", type=int, default=10,
        help="with poses, k-means on the world seen so far every N frames and on the last "
        "(default 10; 0: last frame only)")
    _add_no_progress_option(recording)


def _add_rrd(sub: argparse._SubParsersAction) -> None:
    """``gngdt eval rrd``: a logged run read back."""
    rrd = _leaf(
        sub, "rrd", "what a logged run did, read back from its .rrd",
        "Read a run logged by `gngdt run` or `gngdt log` back from its .rrd file and report "
        "what it did: every metrics/ scalar over the frames (nodes, steps/s, latency, "
        "quantization error, clusters). Writes rrd.md, rrd.json and plots into --out.",
        "  gngdt eval rrd runs/tabletop-20260101-120000.rrd --out report/run\n"
        "  gngdt run recordings/tabletop.mcap --save run.rrd && gngdt eval rrd run.rrd\n")
    rrd.add_argument("path", type=Path, metavar="RUN.rrd", help="rerun recording written by gngdt")
    rrd.add_argument("--out", type=Path, default=None,
                     help="output folder (default: report/<run name>)")


def _add_segmentation(sub: argparse._SubParsersAction) -> None:
    """``gngdt eval segmentation``: the options of `SegmentationEvalSettings`."""
    segmentation = _leaf(
        sub, "segmentation", "gngdt's segments on labelled real frames, beside the Open3D peer",
        "Score gngdt's segmentation on a labelled set (redwood layout + label/: 0 = no label, "
        "1 = background, k >= 2 = a segment): per frame and overall mean best IoU, recall at "
        "IoU >= 0.5 and >= 0.75, segments and time per frame, beside the Open3D peer (plane "
        "RANSAC + DBSCAN) when open3d is installed (pip install -e '.[peers]').",
        "  gngdt eval segmentation ../shared/data/labelled/mosd_learn --out report/mosd\n"
        "  gngdt eval segmentation ../shared/data/labelled/ycbv_0000 --independent --online\n"
        "  gngdt eval segmentation SET --params my_profile.toml --no-peer --max-frames 5\n")
    segmentation.add_argument("set_dir", type=Path, metavar="SET_DIR", help="labelled folder")
    segmentation.add_argument("--out", type=Path, default=None,
                              help="output folder (default: report/<set name>)")
    segmentation.add_argument(
        "--independent", action="store_true",
        help="gngdt learns every frame from scratch")
    segmentation.add_argument(
        "--online", action="store_true",
        help="gngdt carries one network from frame to frame, as `gngdt segment` does (the "
        "default when no mode is given; both flags: both, side by side)")
    segmentation.add_argument("--params", type=Path, metavar="FILE.toml",
                              help="sensor profile (as gngdt segment)")
    segmentation.add_argument("--no-peer", action="store_true", help="do not run the peer")
    segmentation.add_argument(
        "--figures", type=int, default=4,
        help="frames drawn side by side, spread over the set (default: %(default)s)")
    segmentation.add_argument("--max-frames", type=_positive_int, default=None,
                              help="only the first N frames")
    segmentation.add_argument("--seed", type=int, default=0, help="random seed (default: 0)")
    segmentation.add_argument(
        "--damage-depth", type=int, default=None, metavar="SEED",
        help="drop depth from every frame as a structured-light camera does (stripes of "
        "missing rows and columns, holes at depth edges and on dark or glossy spots), drawn "
        "with this seed; every method sees the same frames, scored on the pixels left")
    _add_no_progress_option(segmentation)


def main(args: argparse.Namespace) -> int:
    """Dispatch to the chosen evaluation; bad input is reported as one line, exit code 2."""
    from gngdt.io.errors import RecordingError

    missing = [name for name in ("matplotlib", "sklearn") if importlib.util.find_spec(name) is None]
    if missing:  # checked first: the plots and references come after minutes of learning
        print(f"gngdt eval needs {' and '.join(missing)}: pip install 'gngdt[eval]'",
              file=sys.stderr)
        return 2
    handlers = {"paper": _main_paper, "recording": _main_recording, "rrd": _main_rrd,
                "segmentation": _main_segmentation}
    try:
        return handlers[args.eval_command](args)
    except (ValueError, OSError, RecordingError) as error:
        print(f"gngdt eval {args.eval_command}: {error}", file=sys.stderr)
        return 2


def _main_paper(args: argparse.Namespace) -> int:
    from gngdt.eval.paper import run_paper

    options = {"workers": args.workers} if args.workers else {}
    settings = PaperSettings(
        trials=args.trials,
        stop=args.stop,
        steps=args.steps,
        max_nodes=args.max_nodes,
        color_noise=tuple(args.color_noise),
        frames=tuple(str(folder) for folder in args.frames),
        all_frames=args.all_frames,
        frame_trials=args.frame_trials,
        data1_points=args.data1_points,
        data2_points=args.data2_points,
        scales=tuple(args.scales),
        datasets=tuple(args.datasets),
        methods=_in_paper_order(args.methods),
        min_cluster_size=args.min_cluster_size,
        **options,
    )
    data = run_paper(settings, args.out, progress=not args.no_progress)
    print(f"report: {args.out / 'paper.md'} ({data['wall_seconds']:.1f} s)")
    for claim, check in data["findings"].items():
        if not check["holds"]:
            print(f"  not reproduced: {claim}")
    if data["real_frames"]:
        for claim, check in data["real_frames"]["findings"].items():
            print(f"  {'reproduced' if check['holds'] else 'not reproduced'}: {claim}")
    return 0


def _in_paper_order(methods: list[str]) -> tuple[str, ...]:
    """Chosen methods named as in the paper, in its column order (GNG, GNG-W, GNG-DT)."""
    chosen = {METHOD_NAMES[m] for m in methods}
    return tuple(m for m in METHODS if m in chosen)


def _main_recording(args: argparse.Namespace) -> int:
    from gngdt.eval.recording_eval import RecordingSettings, evaluate_recording

    overrides = {
        name: getattr(args, name)
        for name in (
            "samples_per_frame",
            "max_nodes",
            "min_cluster_size",
            "object_confirm_frames",
            "max_frames",
            "max_points",
            "dbscan_eps",
        )
        if getattr(args, name) is not None
    }
    from gngdt.eval.dynamics import DynamicsSettings

    if args.utility_k is not None:
        if args.utility_k < 0:
            raise ValueError(f"--utility-k must be >= 0, got {args.utility_k}")
        overrides["utility_k"] = args.utility_k or None
    if args.replay_share is not None:
        if not 0 <= args.replay_share < 1:
            raise ValueError(f"--replay-share must be in [0, 1), got {args.replay_share}")
        overrides["replay_share"] = args.replay_share
    if args.reference_every < 0:
        raise ValueError(f"--reference-every must be >= 0, got {args.reference_every}")
    settings = RecordingSettings(
        methods=_in_paper_order(args.methods),
        trials=args.trials,
        reference_points=args.reference_points,
        world_frame=not args.camera_frame,
        settle=args.settle,
        dynamics=DynamicsSettings(ghost_distance_m=args.ghost_distance,
                                  reference_every=args.reference_every,
                                  world_sample=args.world_sample),
        **overrides,
    )
    out = args.out or Path("report") / args.path.stem
    data = evaluate_recording(args.path, settings, out, progress=not args.no_progress)
    print(f"report: {out / 'recording.md'} ({data['wall_seconds']:.1f} s)")
    for method, entry in data["summary"].items():
        ratio = entry.get("ratio_to_kmeans_pos")
        print(
            f"  {method}: position error {entry['qe_pos']['mean']:.4f} m"
            + (f" ({ratio:.2f} x k-means)" if ratio else "")
        )
    return 0


def _main_rrd(args: argparse.Namespace) -> int:
    from gngdt.eval.rrd import evaluate_rrd

    out = args.out or Path("report") / args.path.stem
    data = evaluate_rrd(args.path, out)
    print(f"report: {out / 'rrd.md'} ({len(data['metrics'])} metrics over {data['frames']} frames)")
    return 0


def _main_segmentation(args: argparse.Namespace) -> int:
    from gngdt.eval.segmentation import (
        SegmentationEvalSettings,
        evaluate_segmentation,
    )

    modes = tuple(mode for mode in ("independent", "online") if getattr(args, mode))
    settings = SegmentationEvalSettings(
        modes=modes or ("online",), params=args.params, peer=not args.no_peer,
        figures=args.figures, max_frames=args.max_frames, seed=args.seed,
        damage_seed=args.damage_depth,
    )
    out = args.out or Path("report") / args.set_dir.resolve().name
    data = evaluate_segmentation(args.set_dir, settings, out, progress=not args.no_progress)
    print(f"report: {out / 'segmentation.md'} ({data['wall_seconds']:.1f} s)")
    for method, entry in data["methods"].items():
        summary, total = entry["summary"], entry["milliseconds"]["total"]
        print(f"  {method}: mean best IoU {summary['mean_best_iou']:.3f}, "
              f"R@0.5 {summary['recall_50']:.3f}, R@0.75 {summary['recall_75']:.3f}, "
              f"{summary['segments_per_frame']:.1f} segments/frame, "
              f"{total['p50']:.0f} ms/frame p50; of {summary['truth_segments']} objects "
              f"{summary['fragmented']} fragmented, {summary['merged']} merged, "
              f"{summary['missed']} missed")
    if not data["peer"]["run"]:
        print(f"  peer not run: {data['peer']['status']}")
    return 0
