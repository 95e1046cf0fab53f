"""The paper's simulation experiment (Section 3.1): Tables 2-4 and Figures 8-11, reproduced.

GNG, GNG-W and GNG-DT learn Data1 (2D) and Data2 (3D) at scl ∈ {10, 1, 0.1, 0.01}, at one or more
levels of within-region colour noise, ``trials`` times each with a different sampling seed,
spread over the cores. The paper states neither its node budget nor its colours, so both are ours
and stated in the report; runs stop at the node budget, the criterion of the paper's Step 10.
This module runs the trials; the published numbers and our settings are `paper_common`, the
methods `paper_methods`, the tables and claims `paper_summary`, the real-frame experiment
(Tables 5-6) `paper_rgbd`, the report `paper_report`.
"""

from __future__ import annotations

import logging
import math
import tempfile
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from gngdt.core.clustering import COL, POS
from gngdt.eval.paper_common import (
    GNGDT_THRESHOLDS,
    GNGW_WEIGHTS,
    PAPER_PARAMETERS,
    RECTANGLES,
    PaperSettings,
)
from gngdt.eval.paper_methods import clusterings_of, learn, make_model, trial_seed
from gngdt.eval.paper_report import render_markdown, write_plots
from gngdt.eval.paper_rgbd import (
    build_frame_tasks,
    extract_frames,
    frame_findings,
    summarise_frames,
)
from gngdt.eval.paper_summary import colour_fit, differences, findings, select_runs, summarise
from gngdt.eval.progress import ProgressBar
from gngdt.eval.report import write_report

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class TrialTask:
    """One run: a method learning one dataset at one scale with one sampling seed."""

    method: str
    dataset: str
    scale: float
    trial: int
    settings: PaperSettings
    color_noise: float = 0.0
    #: return the learned topology too (for the Figures 8/9 drawings)
    keep_topology: bool = False

    def run(self) -> dict[str, Any]:
        return run_trial(self)


@lru_cache(maxsize=4)
def load_dataset(
    dataset: str, scale: float, n_points: int, seed: int, color_noise: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(positions (N, D) float64 scaled by ``scale``, colors (N, 3) 0-255, labels (N,) int).

    The same point cloud serves every trial (as in the paper: one dataset, random sampling per
    trial); cached per process.
    """
    from gngdt.eval.synthetic import make_data1, make_data2

    make = make_data1 if dataset == "Data1" else make_data2
    positions, colors, labels = make(
        scl=scale, n_points=n_points, random_state=seed, color_noise=color_noise
    )
    return np.asarray(positions), np.asarray(colors), np.asarray(labels)


def run_trial(task: TrialTask) -> dict[str, Any]:
    """Learn one run and measure it: quantization errors, clusters, ARI, cluster-centre errors."""
    from gngdt.core import (
        adjusted_rand_index,
        cluster_centre_errors,
        cluster_count,
        quantization_error,
    )

    settings = task.settings
    n_points = settings.data1_points if task.dataset == "Data1" else settings.data2_points
    positions, colors, labels = load_dataset(
        task.dataset, task.scale, n_points, settings.data_seed, task.color_noise
    )
    seed = trial_seed(task.trial)
    model = make_model(task.method, settings.max_nodes, seed)
    started = time.perf_counter()
    learn(model, positions, colors, settings.stop, settings.steps)
    learn_seconds = time.perf_counter() - started

    winners = model.predict(positions)  # once: eq. 17 and the ARI below share them
    error = {POS: quantization_error(positions, model.positions_, winners),
             COL: quantization_error(colors, model.colors_, winners)}
    result: dict[str, Any] = {
        "kind": "simulation",
        "method": task.method,
        "dataset": task.dataset,
        "scale": task.scale,
        "color_noise": task.color_noise,
        "trial": task.trial,
        "seed": seed,
        "nodes": int(model.n_nodes_),
        "steps": int(model.n_steps_),
        "learn_seconds": learn_seconds,
        "qe_pos": float(error[POS]),
        "qe_col": float(error[COL]),
        "clusters": {},
        "clusters_all": {},
        "ari": {},
    }
    topology: dict[str, Any] = {"positions": model.positions_, "edges": {}, "labels": {}}
    for props in clusterings_of(task.method, positions.shape[1]):
        name = "+".join(props)
        node_labels = np.asarray(model.clusters(*props, min_size=settings.min_cluster_size))
        result["clusters"][name] = cluster_count(node_labels)
        all_labels = np.asarray(model.clusters(*props))
        result["clusters_all"][name] = len(np.unique(all_labels))
        result["ari"][name] = float(adjusted_rand_index(labels, node_labels[winners]))
        topology["labels"][name] = node_labels
        topology["edges"][name] = model.edges(*props)

    if task.method == "GNG-DT" and task.dataset == "Data1":
        col_labels = np.asarray(model.clusters(COL, min_size=settings.min_cluster_size))
        centres = data1_centres(task.scale)
        centre_errors = cluster_centre_errors(model.positions_, col_labels, centres)
        result["centre_errors"] = dict(zip(RECTANGLES, map(float, centre_errors), strict=True))
        # the same error with every node of each rectangle, clustered or not: what is left is
        # the network's own placement, the rest is the nodes the colour clusters leave out
        quadrant = np.sum((model.positions_ >= 150.0 * task.scale) * [1, 2], axis=1)
        all_nodes = cluster_centre_errors(model.positions_, quadrant, centres)
        result["centre_errors_all_nodes"] = dict(zip(RECTANGLES, map(float, all_nodes),
                                                     strict=True))
        result["nodes_outside_colour_clusters"] = int(np.sum(col_labels < 0))
    if task.method == "GNG-DT" and task.dataset == "Data2":
        result["normal_edges"] = normal_edge_spread(model, winners, labels)
    if task.dataset == "Data1":
        # the clustering that should find the rectangles: GNG-DT's colour topology, else the one
        main = COL if task.method == "GNG-DT" else POS
        result["rectangles_separated"] = separates_regions(
            labels, topology["labels"][main][winners], len(RECTANGLES)
        )
    if task.keep_topology:
        result["topology"] = topology
    return result


def normal_edge_spread(model: Any, winners: np.ndarray, labels: np.ndarray) -> dict[str, Any]:
    """Per Data2 surface: how far apart the normals of position neighbours are (eq. 4's test).

    A node belongs to the surface most of the points it wins lie on. For the position edges with
    both ends on one surface: the median sign-invariant normal distance and the share below
    tau_nor (those edges are the surface's normal topology).
    """
    from gngdt.eval.synthetic import (
        DATA2_CYLINDER,
        DATA2_FLOOR,
        DATA2_PRISM_BROWN_FACE,
        DATA2_PRISM_RED_FACE,
    )

    surfaces = {"floor": DATA2_FLOOR, "prism red face": DATA2_PRISM_RED_FACE,
                "prism brown face": DATA2_PRISM_BROWN_FACE, "half cylinder": DATA2_CYLINDER}
    counts = np.zeros((model.n_nodes_, len(surfaces)), dtype=np.int64)
    np.add.at(counts, (winners, labels), 1)
    node_surface = np.where(counts.sum(axis=1) > 0, counts.argmax(axis=1), -1)
    edges = model.edges(POS)
    normals = model.normals_
    difference = normals[edges[:, 0]] - normals[edges[:, 1]]
    total = normals[edges[:, 0]] + normals[edges[:, 1]]
    distance = np.minimum(np.linalg.norm(difference, axis=1), np.linalg.norm(total, axis=1))
    spread = {}
    for name, surface in surfaces.items():
        inside = (node_surface[edges[:, 0]] == surface) & (node_surface[edges[:, 1]] == surface)
        values = distance[inside]
        spread[name] = {
            "edges": int(values.size),
            "median": float(np.median(values)) if values.size else math.nan,
            "below_tau": float(np.mean(values < model.tau_nor)) if values.size else math.nan,
        }
    return spread


def separates_regions(
    truth: np.ndarray, predicted: np.ndarray, regions: int, purity: float = 0.9
) -> bool:
    """True when ``predicted`` has exactly ``regions`` clusters, each a different true region.

    truth, predicted: (N,) int labels per point (predicted -1 = a node in no counted cluster;
    those points are left out). Each cluster must hold >= ``purity`` of its points from one
    region, and the clusters' majority regions must all differ.
    """
    counted = predicted >= 0
    clusters = np.unique(predicted[counted])
    if clusters.size != regions:
        return False
    majorities = set()
    for cluster in clusters:
        members = truth[counted][predicted[counted] == cluster]
        values, counts = np.unique(members, return_counts=True)
        if counts.max() < purity * members.size:
            return False
        majorities.add(int(values[np.argmax(counts)]))
    return len(majorities) == regions


def data1_centres(scale: float) -> np.ndarray:
    """(4, 2) true centres of Data1's rectangles C1..C4 (Section 3.1.1) times ``scale``."""
    from gngdt.eval.synthetic import DATA1_CENTRES

    return scale * np.asarray(DATA1_CENTRES, dtype=np.float64)


def build_tasks(settings: PaperSettings) -> list[TrialTask]:
    """Every (noise level, dataset, scale, method, trial) run; trial 0 of the main noise level
    keeps its topology for the drawings.

    Data2 runs come first so the slowest work starts early and the pool ends evenly.
    """
    return [
        TrialTask(method, dataset, scale, trial, settings, noise,
                  keep_topology=trial == 0 and noise == settings.color_noise[0])
        for dataset in sorted(settings.datasets, reverse=True)
        for noise in settings.color_noise
        for scale in settings.scales
        for trial in range(settings.trials)
        for method in settings.methods
    ]


def run_trials(
    tasks: Sequence[Any],
    workers: int,
    on_done: Callable[[dict[str, Any]], None] | None = None,
) -> list[dict[str, Any]]:
    """``task.run()`` for every task on ``workers`` processes (in this process when 1); results
    in task order."""
    results: list[dict[str, Any] | None] = [None] * len(tasks)
    if workers <= 1:
        for index, task in enumerate(tasks):
            results[index] = task.run()
            if on_done:
                on_done(results[index])
        return results  # type: ignore[return-value]
    with ProcessPoolExecutor(max_workers=workers) as pool:
        futures = {pool.submit(_run_task, task): index for index, task in enumerate(tasks)}
        for future in as_completed(futures):
            results[futures[future]] = future.result()
            if on_done:
                on_done(results[futures[future]])
    return results  # type: ignore[return-value]


def _run_task(task: Any) -> dict[str, Any]:
    return task.run()


def summarise_levels(simulation: list[dict[str, Any]],
                     settings: PaperSettings) -> dict[float, dict[str, Any]]:
    """Per colour-noise level: its ``tables``, the paper's claims checked on them (``findings``)
    and how well the level fits the paper's baselines (``fit``)."""
    levels = {}
    for level in settings.color_noise:
        tables = summarise(select_runs(simulation, color_noise=level), settings)
        levels[level] = {"tables": tables, "findings": findings(tables, settings),
                         "fit": colour_fit(tables)}
    return levels


def run_paper(
    settings: PaperSettings, out_dir: str | Path, progress: bool = True
) -> dict[str, Any]:
    """Run the whole experiment and write ``paper.md``, ``paper.json`` and PNGs into ``out_dir``.

    RecordingError when a folder of ``settings.frames`` cannot be read (before any learning).
    """
    out_dir = Path(out_dir)
    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="gngdt-frames-") as frame_dir:
        frames = extract_frames(settings.frames, settings.all_frames, Path(frame_dir))
        frame_trials = settings.frame_trials or settings.trials
        # the real frames are the slowest runs: first, so the pool ends evenly
        tasks = build_frame_tasks(frames, settings, frame_trials) + build_tasks(settings)
        bar = ProgressBar(len(tasks), label="runs") if progress else None
        workers = min(settings.workers, len(tasks))
        log.info("eval paper: %d runs on %d worker(s)", len(tasks), workers)
        results = run_trials(tasks, workers, on_done=(lambda _r: bar.advance()) if bar else None)
    wall_seconds = time.perf_counter() - started
    if bar:
        bar.close()

    simulation = select_runs(results, kind="simulation")
    topologies = {
        (r["dataset"], r["method"], r["scale"]): r.pop("topology")
        for r in simulation
        if "topology" in r
    }
    levels = summarise_levels(simulation, settings)
    main = levels[settings.color_noise[0]]
    real_frames = None
    if frames:
        frame_results = select_runs(results, kind="frame")
        frame_tables = summarise_frames(frame_results, frames, settings.methods)
        real_frames = {"trials": frame_trials, "frames": [asdict(f) for f in frames],
                       "tables": frame_tables,
                       "findings": frame_findings(frame_tables, settings.methods)}
    plots = write_plots(main["tables"], topologies, settings, out_dir)
    data = {
        "settings": asdict(settings),
        "parameters": {
            "table1": PAPER_PARAMETERS,
            "gngdt": GNGDT_THRESHOLDS,
            "gngw": GNGW_WEIGHTS,
        },
        "wall_seconds": wall_seconds,
        "cpu_seconds_learning": sum(r["learn_seconds"] for r in simulation),
        "learning": {
            "steps_min": min(r["steps"] for r in results),
            "steps_max": max(r["steps"] for r in results),
            "nodes_min": min(r["nodes"] for r in results),
            "nodes_max": max(r["nodes"] for r in results),
        },
        "color_noise": settings.color_noise[0],
        "tables": main["tables"],
        "findings": main["findings"],
        "differences": differences(main["tables"]),
        "levels": levels,
        "real_frames": real_frames,
        "trials": results,
        "plots": [p.name for p in plots],
    }
    markdown = render_markdown(data, settings, plots)
    write_report(out_dir, "paper", markdown, data)
    return data
