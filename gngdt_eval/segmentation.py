"""``gngdt eval segmentation``: gngdt's segments on a labelled set of real frames, scored per
frame and overall beside the classic peer (Open3D plane RANSAC + DBSCAN) in the same run.

A labelled set is a folder of frames (the ``redwood`` layout: ``color/``, ``depth/``,
``camera.json``) plus ``label/<name>.png`` per frame, uint16: 0 = no label (no depth), 1 =
background, k >= 2 = a ground-truth segment (``../shared/data/labelled/README.md``). Scores:
`gngdt.eval.segment_scores`. gngdt runs through the same code as ``gngdt segment``
(`gngdt.services.segment.segment_frames`), in each mode asked for.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from gngdt.eval.open3d_peer import PeerParams
from gngdt.eval.report import format_number, markdown_table, write_report
from gngdt.eval.segment_scores import FAILURES, RECALL_THRESHOLDS, recall_key
from gngdt.eval.segmentation_damage import DamagedSource, DepthDamage

log = logging.getLogger(__name__)

MODES = ("independent", "online")
PEER = "open3d peer"
LABEL_FOLDER = "label"


@dataclass
class SegmentationEvalSettings:
    """What ``gngdt eval segmentation`` runs."""

    #: gngdt modes, each a method of its own: "independent" and/or "online"
    modes: tuple[str, ...] = ("independent",)
    #: sensor profile TOML (None: the default profile)
    params: Path | None = None
    #: run the Open3D peer when open3d can be imported
    peer: bool = True
    peer_params: PeerParams = field(default_factory=PeerParams)
    #: frames drawn side by side (colour, ground truth, each method), spread over the set
    figures: int = 4
    #: and the frames where gngdt did worst (lowest mean best IoU over its modes)
    worst: int = 4
    #: only the first N frames (None: all)
    max_frames: int | None = None
    seed: int = 0
    #: drop depth from every frame as a structured-light camera does, seeded by this (None:
    #: the frames as recorded); every method sees the same damaged frames
    damage_seed: int | None = None
    damage: DepthDamage = field(default_factory=DepthDamage)

    def validate(self) -> None:
        unknown = sorted(set(self.modes) - set(MODES))
        if unknown or not self.modes:
            raise ValueError(f"modes must be among {MODES}, got {list(self.modes)}")
        if min(self.figures, self.worst) < 0 or (self.max_frames is not None
                                                 and self.max_frames < 1):
            raise ValueError("figures and worst must be >= 0 and max_frames >= 1")


def method_name(mode: str) -> str:
    return f"gngdt {mode}"


def read_truth(set_dir: Path, name: str, shape: tuple[int, int], index: int) -> np.ndarray:
    """(H, W) uint16 ground truth of frame ``name``; RecordingError naming the file when it is
    missing, unreadable or not of the frame's size."""
    import cv2

    from gngdt.io.errors import RecordingError

    path = set_dir / LABEL_FOLDER / f"{name}.png"
    if not path.is_file():
        raise RecordingError(path, index, "missing ground-truth label image")
    truth = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if truth is None or truth.ndim != 2 or truth.dtype not in (np.uint8, np.uint16):
        raise RecordingError(path, index, "cannot read it as a single-channel label image")
    if truth.shape != shape:
        raise RecordingError(path, index, f"labels {truth.shape[1]}x{truth.shape[0]} do not "
                                          f"match the frame's {shape[1]}x{shape[0]}")
    return truth


@dataclass
class _Frame:
    """What is kept of one frame for the report."""

    name: str
    truth: np.ndarray
    valid: np.ndarray
    color: np.ndarray | None  # only for frames drawn


def _limited(items: Iterator, max_frames: int | None) -> Iterator:
    for index, item in enumerate(items):
        if max_frames is not None and index >= max_frames:
            return
        yield item


def evaluate_segmentation(set_dir: str | Path, settings: SegmentationEvalSettings, out: Path,
                          progress: bool = True) -> dict[str, Any]:
    """Run every method on the labelled set, score it and write the report into ``out``
    (``segmentation.md``, ``segmentation.json``, ``segmentation_<frame>.png``); returns the
    report's data."""
    from gngdt.eval.open3d_peer import Open3DPeer, load_open3d
    from gngdt.io.profiles import load_sensor_profile
    from gngdt.io.segment_frames import make_segmenter, organized_frames, segment_frames
    from gngdt.io.sources import open_source

    settings.validate()
    set_dir = Path(set_dir)
    started = time.perf_counter()
    profile = load_sensor_profile(settings.params)
    source = open_source(set_dir)
    if settings.damage_seed is not None:
        source = DamagedSource(source, settings.damage, settings.damage_seed)
    frames: list[_Frame] = []
    for name, frame in _limited(source.frames(), settings.max_frames):  # fail before any work
        truth = read_truth(set_dir, name, frame.depth.shape, frame.index)
        frames.append(_Frame(name, truth, (frame.depth > 0) & (truth != 0), None))
    spread = _spread(len(frames), settings.figures)
    log.info("%s: %d frames, methods: %s", set_dir, len(frames),
             ", ".join(method_name(mode) for mode in settings.modes))

    runs = _MethodRuns(frames, progress)

    for mode in settings.modes:
        segmenter = make_segmenter(profile, settings.seed)
        items = _limited(segment_frames(source, segmenter, mode == "independent"),
                         settings.max_frames)
        runs.run(method_name(mode), ((item.result.labels, item.milliseconds,
                                 {"nodes": item.result.n_nodes, "steps": item.result.steps})
                                for item in items))

    open3d, peer_note = load_open3d() if settings.peer else (None, "not requested (--no-peer)")
    if open3d is not None:
        peer = Open3DPeer(open3d, settings.peer_params)
        runs.run(PEER, _peer_labels(peer, _limited(organized_frames(source), settings.max_frames)))
    else:
        log.warning("the peer was not run: %s", peer_note)

    methods, predictions = runs.methods, runs.predictions
    worst = _worst_frames(methods, settings.worst)
    drawn = sorted(set(spread) | set(worst))
    for index, (_, frame, _, _) in enumerate(_limited(organized_frames(source),
                                                      settings.max_frames)):
        if index in drawn:
            frames[index].color = frame.color
    data = {
        "set": str(set_dir), "frames": len(frames), "format": source.format,
        "intrinsics_from": source.camera_note,
        "score": "per ground-truth segment (label >= 2) the best IoU over the predicted "
                 "segments, on pixels with depth and a label (0 ignored; 1 = background counts "
                 "in predicted segments; unassigned pixels count against); mean and recalls "
                 "pooled over every ground-truth segment of the set",
        "gngdt": {"modes": list(settings.modes), "parameters": profile.as_dict(),
                  "random_state": settings.seed},
        "damage": None if settings.damage_seed is None else {
            "seed": settings.damage_seed, "description": settings.damage.describe(),
            **settings.damage.as_dict()},
        "peer": {"run": open3d is not None, "status": peer_note,
                 "parameters": settings.peer_params.as_dict(),
                 "description": settings.peer_params.describe()},
        "methods": methods,
    }
    data["worst_frames"] = [frames[index].name for index in worst]
    data["figures"] = _figures(out, frames, predictions, drawn, set_dir.name,
                               set(worst) - set(spread))
    data["wall_seconds"] = time.perf_counter() - started
    write_report(out, "segmentation", _markdown(data), data)
    return data


class _MethodRuns:
    """Each method's labels of every frame, scored (``methods``: summary and per-frame records
    with failure counts), and kept PNG-compressed (``predictions``, a few kB a frame) until the
    frames to draw, gngdt's worst among them, are known."""

    def __init__(self, frames: list[_Frame], progress: bool) -> None:
        self.frames = frames
        self.progress = progress
        self.methods: dict[str, dict[str, Any]] = {}
        self.predictions: dict[str, list[bytes]] = {}

    def run(self, method: str,
            labelled: Iterator[tuple[np.ndarray, dict[str, float], dict]]) -> None:
        from gngdt.eval.progress import ProgressBar
        from gngdt.eval.segment_scores import score_frame

        bar = ProgressBar(len(self.frames), method) if self.progress else None
        records, scores, encoded = [], [], []
        for index, (labels, milliseconds, extra) in enumerate(labelled):
            kept = self.frames[index]
            score = score_frame(kept.truth, labels, kept.valid)
            scores.append(score)
            records.append({"name": kept.name, "mean_best_iou": score.mean_best_iou,
                            **{recall_key(t): score.recall(t) for t in RECALL_THRESHOLDS},
                            "truth_segments": len(score.best_iou),
                            "segments": score.n_predicted, "best_iou": score.best_iou,
                            **score.failure_counts.as_dict(),
                            "milliseconds": milliseconds, **extra})
            encoded.append(_encode_labels(labels))
            if bar:
                bar.advance()
        if bar:
            bar.close()
        self.methods[method] = _method_summary(scores, records)
        self.predictions[method] = encoded


def _peer_labels(peer: Any, items: Iterator[tuple[str, Any, np.ndarray, float]]
                 ) -> Iterator[tuple[np.ndarray, dict[str, float], dict]]:
    for _, _, points, deproject_ms in items:
        labels, laps = peer.segment(points)
        milliseconds = {"deproject": deproject_ms, **laps}
        milliseconds["total"] = sum(milliseconds.values())
        yield labels, milliseconds, {}


def _encode_labels(labels: np.ndarray) -> bytes:
    import cv2

    return cv2.imencode(".png", np.clip(labels, 0, 65535).astype(np.uint16))[1].tobytes()


def _decode_labels(encoded: bytes) -> np.ndarray:
    import cv2

    return cv2.imdecode(np.frombuffer(encoded, dtype=np.uint8), cv2.IMREAD_UNCHANGED)


def _worst_frames(methods: dict[str, dict[str, Any]], wanted: int) -> list[int]:
    """Indices of up to ``wanted`` frames with the lowest mean best IoU of any gngdt mode
    (frames without ground-truth segments never), worst first."""
    worst: dict[int, float] = {}
    for name, method in methods.items():
        if name == PEER:
            continue
        for index, record in enumerate(method["per_frame"]):
            if record["truth_segments"]:
                worst[index] = min(worst.get(index, 1.0), record["mean_best_iou"])
    return sorted(worst, key=lambda index: (worst[index], index))[:wanted]


def _spread(count: int, wanted: int) -> list[int]:
    """Up to ``wanted`` frame indices spread evenly over ``count`` frames (first and last in)."""
    if count == 0 or wanted == 0:
        return []
    return sorted({round(float(i)) for i in np.linspace(0, count - 1, min(wanted, count))})


def _method_summary(scores: list, records: list[dict[str, Any]]) -> dict[str, Any]:
    from gngdt.eval.segment_scores import summarize_scores
    from gngdt.io.segment_frames import timing_summary

    return {"summary": summarize_scores(scores),
            "milliseconds": timing_summary([record["milliseconds"] for record in records]),
            "per_frame": records}


def _figures(out: Path, frames: list[_Frame], predictions: dict[str, list[bytes]],
             drawn: list[int], set_name: str, worst: set[int]) -> list[str]:
    from gngdt.eval.plots import label_image_colours, plot_image_rows

    paths = []
    for index in drawn:
        frame = frames[index]
        row = [(f"colour {frame.name}", frame.color),
               (f"ground truth ({len(np.unique(frame.truth[frame.truth >= 2]))} segments)",
                label_image_colours(frame.truth))]
        for method, encoded in predictions.items():
            labels = _decode_labels(encoded[index])
            row.append((method, label_image_colours(np.where(frame.valid, labels, 0))))
        note = " (among gngdt's worst)" if index in worst else ""
        path = plot_image_rows([row], out / f"segmentation_{frame.name}.png",
                               title=f"{set_name} frame {frame.name}{note}")
        paths.append(path.name)
    return paths


def _markdown(data: dict[str, Any]) -> str:
    methods = data["methods"]
    lines = [f"# Segmentation: {Path(data['set']).name} ({data['frames']} frames)", "",
             f"Set `{data['set']}` ({data['format']}; intrinsics from {data['intrinsics_from']}).",
             "", f"Score: {data['score']}.", "",
             *([] if data["damage"] is None else [
                 f"Depth damaged (seed {data['damage']['seed']}): "
                 f"{data['damage']['description']}; scored on the pixels that keep their "
                 "depth.", ""]),
             f"gngdt: modes {', '.join(data['gngdt']['modes'])}; profile "
             f"`{data['gngdt']['parameters']['profile']}`, seed {data['gngdt']['random_state']}.",
             ""]
    for table in ("gngdt", "segmentation", "frames"):
        values = data["gngdt"]["parameters"][table]
        lines.append(f"- `[{table}]` " + ", ".join(f"{k} = {v}" for k, v in values.items()))
    peer = data["peer"]
    lines += ["", f"Peer: {peer['description']}." if peer["run"]
              else f"**Peer not run**: {peer['status']}.", ""]
    lines += ["## Overall", "", markdown_table(
        ["method", "mean best IoU", "R@0.5", "R@0.75", "segments / frame", "ms / frame p50",
         "ms / frame p90"],
        [[name, format_number(m["summary"]["mean_best_iou"]),
          format_number(m["summary"]["recall_50"]), format_number(m["summary"]["recall_75"]),
          format_number(m["summary"]["segments_per_frame"], 1),
          format_number(m["milliseconds"]["total"]["p50"], 0),
          format_number(m["milliseconds"]["total"]["p90"], 0)] for name, m in methods.items()]),
        ""]
    if methods:
        truth = next(iter(methods.values()))["summary"]["truth_segments"]
        lines += [f"{truth} ground-truth segments in all. Time: wall clock per frame, "
                  "deprojection included, on a machine possibly shared with other jobs.", ""]
        lines += ["## Failures", "", "Ground-truth segments (objects) by how they failed, of "
                  f"{truth} (one can fail in more than one way): fragmented = the predicted "
                  "segment covering most of it covers < 80 % of it; merged = that segment also "
                  "covers > 20 % of another object; missed = no predicted segment is mostly "
                  "this object (into the background, another object, or unassigned).", "",
                  markdown_table(["method", *FAILURES],
                                 [[name, *(m["summary"][key] for key in FAILURES)]
                                  for name, m in methods.items()]), ""]
    lines += ["## Time per phase (ms, p50 / p90)", ""]
    for name, m in methods.items():
        lines.append(f"- {name}: " + ", ".join(
            f"{phase} {stats['p50']:.0f} / {stats['p90']:.0f}"
            for phase, stats in m["milliseconds"].items()))
    lines += ["", "## Per frame", ""]
    for name, m in methods.items():
        lines += [f"### {name}", "", markdown_table(
            ["frame", "GT segments", "mean best IoU", "R@0.5", "R@0.75", "segments",
             *FAILURES, "ms"],
            [[r["name"], r["truth_segments"], format_number(r["mean_best_iou"]),
              format_number(r["recall_50"], 2), format_number(r["recall_75"], 2),
              r["segments"], *(r[key] for key in FAILURES),
              format_number(r["milliseconds"]["total"], 0)]
             for r in m["per_frame"]]), ""]
    if data["figures"]:
        lines += ["## Frames side by side", "",
                  "Spread over the set, and gngdt's worst frames "
                  f"({', '.join(data['worst_frames']) or 'none'}: lowest mean best IoU). ",
                  "Black: no depth / no segment; grey: label 1 (ground truth: background; "
                  "gngdt: its largest segment; peer: the plane); other colours per label "
                  "(colours are not matched across panels).", ""]
        lines += [f"![{path}]({path})" for path in data["figures"]]
    return "\n".join(lines)

