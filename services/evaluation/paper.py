"""The paper's simulation experiment (Section 3.1): Tables 2, 3 and 4 and Figure 10, reproduced.

GNG, GNG-W and GNG-DT learn Data1 (2D) and Data2 (3D) at scl ∈ {10, 1, 0.1, 0.01}, ``trials``
times each with a different sampling seed, spread over the cores. The paper does not state how long
each run learns nor how many nodes it may grow, so both are ours and stated in the report:
every run learns a fixed number of steps (samples drawn in random order) with a node budget.
"""

from __future__ import annotations

import logging
import math
import os
import time
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from services.evaluation.report import (
    format_mean_std,
    format_number,
    markdown_table,
    mean_std,
    write_report,
)

log = logging.getLogger(__name__)

METHODS = ("GNG", "GNG-W", "GNG-DT")
#: command-line method names -> the paper's names
METHOD_NAMES = {"gngdt": "GNG-DT", "gng": "GNG", "gngw": "GNG-W"}
DATASETS = ("Data1", "Data2")
#: scales in the order the paper's tables list them
SCALES = (1.0, 10.0, 0.1, 0.01)
RECTANGLES = ("C1", "C2", "C3", "C4")

#: Table 1 of the paper (shared by all three methods; tau_* only concern GNG-DT).
PAPER_PARAMETERS: dict[str, float] = {
    "lambda_": 500,
    "eta1": 0.025,
    "eta2": 0.0003,
    "age_max": 88,
    "alpha": 0.5,
    "beta": 0.0005,
}
GNGDT_THRESHOLDS: dict[str, float] = {"tau_col": 10.0, "tau_nor": 0.02}
#: Section 3.1.1: GNG-W weights, from the paper's reference [47].
GNGW_WEIGHTS: dict[str, float] = {"w_pos": 0.8, "w_col": 0.2}

Cell = tuple[float, float]  # (mean, std) as published

# Table 2 of the paper: quantization error of position (eq. 17), mean ± std over 50 trials.
PAPER_TABLE2: dict[str, dict[str, dict[float, Cell]]] = {
    "Data1": {
        "GNG": {
            1.0: (8.687, 0.062),
            10.0: (73.948, 0.191),
            0.1: (1.311, 0.020),
            0.01: (0.248, 0.009),
        },
        "GNG-W": {
            1.0: (7.794, 0.037),
            10.0: (73.581, 0.217),
            0.1: (1.144, 0.015),
            0.01: (0.190, 0.003),
        },
        "GNG-DT": {
            1.0: (7.341, 0.022),
            10.0: (73.434, 0.199),
            0.1: (0.735, 0.002),
            0.01: (0.073, 0.000),
        },
    },
    "Data2": {
        "GNG": {
            1.0: (11.825, 0.047),
            10.0: (103.064, 0.311),
            0.1: (1.644, 0.010),
            0.01: (0.279, 0.003),
        },
        "GNG-W": {
            1.0: (11.133, 0.038),
            10.0: (103.224, 0.293),
            0.1: (1.456, 0.008),
            0.01: (0.234, 0.002),
        },
        "GNG-DT": {
            1.0: (10.341, 0.021),
            10.0: (103.418, 0.322),
            0.1: (1.0349, 0.002),
            0.01: (0.103, 0.000),
        },
    },
}

# Table 3 of the paper: quantization error of colour (eq. 17), mean ± std over 50 trials.
PAPER_TABLE3: dict[str, dict[str, dict[float, Cell]]] = {
    "Data1": {
        "GNG": {
            1.0: (25.152, 0.499),
            10.0: (21.094, 0.554),
            0.1: (28.619, 0.682),
            0.01: (33.693, 1.891),
        },
        "GNG-W": {
            1.0: (22.583, 0.567),
            10.0: (23.081, 0.623),
            0.1: (27.623, 0.650),
            0.01: (30.425, 1.005),
        },
        "GNG-DT": {
            1.0: (26.178, 0.425),
            10.0: (26.168, 0.509),
            0.1: (26.072, 0.534),
            0.01: (26.094, 0.475),
        },
    },
    "Data2": {
        "GNG": {
            1.0: (46.740, 0.290),
            10.0: (34.099, 0.055),
            0.1: (48.084, 0.496),
            0.01: (49.462, 1.301),
        },
        "GNG-W": {
            1.0: (45.396, 0.233),
            10.0: (33.933, 0.028),
            0.1: (47.841, 0.419),
            0.01: (48.056, 0.766),
        },
        "GNG-DT": {
            1.0: (33.925, 0.034),
            10.0: (33.919, 0.032),
            0.1: (33.915, 0.031),
            0.01: (33.915, 0.034),
        },
    },
}

# Table 4 of the paper: GNG-DT's cluster-centre error e_i (eq. 18) of C^col on Data1.
# The published table repeats its "C2 (scl = 10.0)" row where C2 at scl = 0.1 belongs, so C2 at
# scl = 0.1 was never published (None here).
PAPER_TABLE4: dict[str, dict[float, Cell | None]] = {
    "C1": {1.0: (5.691, 1.520), 10.0: (57.654, 15.035), 0.1: (0.541, 0.152), 0.01: (0.058, 0.019)},
    "C2": {1.0: (5.691, 1.809), 10.0: (57.562, 14.653), 0.1: None, 0.01: (0.053, 0.014)},
    "C3": {1.0: (5.518, 1.759), 10.0: (56.296, 19.622), 0.1: (0.601, 0.191), 0.01: (0.055, 0.016)},
    "C4": {1.0: (5.830, 1.700), 10.0: (57.493, 16.728), 0.1: (0.564, 0.165), 0.01: (0.056, 0.016)},
}


# Figure 11 of the paper (Section 3.1): GNG-DT's cluster counts on Data2 per topology.
PAPER_FIGURE11_CLUSTERS: dict[str, int] = {"pos": 1, "col": 3, "nor": 4, "col+nor": 5}


@dataclass(frozen=True)
class PaperSettings:
    """How the experiment is run. ``steps`` and ``max_nodes`` are our stopping rule/node budget.

    Defaults: 150,000 learning steps per run with a 250-node budget. One node is inserted every
    lambda = 500 steps, so growth stops at step ~125,000 and the last 25,000 steps only adapt;
    every method ends with the same number of nodes (a fair comparison of the errors). 250 nodes
    puts GNG-DT's Data1 position error at scl = 1 near the paper's 7.34.
    """

    trials: int = 50
    steps: int = 150_000
    max_nodes: int = 250
    data1_points: int = 10_000
    data2_points: int = 112_500
    scales: tuple[float, ...] = SCALES
    datasets: tuple[str, ...] = DATASETS
    methods: tuple[str, ...] = METHODS
    #: clusters with fewer nodes are not counted (the paper's isolated boundary nodes)
    min_cluster_size: int = 5
    workers: int = field(default_factory=lambda: os.cpu_count() or 1)
    data_seed: int = 0

    def __post_init__(self) -> None:
        for name in ("trials", "steps", "max_nodes", "data1_points", "data2_points", "workers"):
            if getattr(self, name) < 1:
                raise ValueError(f"{name} must be >= 1, got {getattr(self, name)}")
        if self.max_nodes < 2:
            raise ValueError(f"max_nodes must be >= 2, got {self.max_nodes}")
        if self.min_cluster_size < 1:
            raise ValueError(f"min_cluster_size must be >= 1, got {self.min_cluster_size}")
        for scale in self.scales:
            if not scale > 0:
                raise ValueError(f"scales must be > 0, got {scale}")
        for dataset in self.datasets:
            if dataset not in DATASETS:
                raise ValueError(f"datasets: unknown {dataset!r} (choose from {DATASETS})")
        for method in self.methods:
            if method not in METHODS:
                raise ValueError(f"methods: unknown {method!r} (choose from {METHODS})")


@dataclass(frozen=True)
class TrialTask:
    """One run: a method learning one dataset at one scale with one sampling seed."""

    method: str
    dataset: str
    scale: float
    trial: int
    settings: PaperSettings
    #: return the learned topology too (for the Figures 8/9 drawings)
    keep_topology: bool = False


@lru_cache(maxsize=4)
def load_dataset(
    dataset: str, scale: float, n_points: int, seed: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(positions (N, D) float64 scaled by ``scale``, colors (N, 3) 0-255, labels (N,) int).

    The same point cloud serves every trial (as in the paper: one dataset, random sampling per
    trial); cached per process.
    """
    from gngdt_core import make_data1, make_data2

    make = make_data1 if dataset == "Data1" else make_data2
    positions, colors, labels = make(scl=scale, n_points=n_points, random_state=seed)
    return np.asarray(positions), np.asarray(colors), np.asarray(labels)


def make_model(method: str, max_nodes: int, random_state: int, **gngdt_extra: Any):
    """A fresh estimator for ``method`` with the paper's Table 1 parameters; ``gngdt_extra``:
    further GNG-DT arguments (forgetting), refused for the other methods."""
    from gngdt_core import GNG, GNGDT, GNGW

    if gngdt_extra and method != "GNG-DT":
        raise ValueError(f"{method} takes no {sorted(gngdt_extra)}")
    if method == "GNG-DT":
        return GNGDT(
            max_nodes=max_nodes, random_state=random_state, **PAPER_PARAMETERS, **GNGDT_THRESHOLDS,
            **gngdt_extra,
        )
    if method == "GNG-W":
        return GNGW(
            max_nodes=max_nodes, random_state=random_state, **PAPER_PARAMETERS, **GNGW_WEIGHTS
        )
    if method == "GNG":
        return GNG(max_nodes=max_nodes, random_state=random_state, **PAPER_PARAMETERS)
    raise ValueError(f"method: unknown {method!r} (choose from {METHODS})")


def clusterings_of(method: str, dimensions: int) -> tuple[tuple[str, ...], ...]:
    """The clusterings to count for a method: GNG-DT's topologies (normals only in 3D), else pos."""
    if method != "GNG-DT":
        return (("pos",),)
    if dimensions == 3:
        return (("pos",), ("col",), ("nor",), ("col", "nor"))
    return (("pos",), ("col",))


def run_trial(task: TrialTask) -> dict[str, Any]:
    """Learn one run and measure it: quantization errors, clusters, ARI, cluster-centre errors."""
    from gngdt_core import adjusted_rand_index, cluster_centre_errors, cluster_count

    settings = task.settings
    n_points = settings.data1_points if task.dataset == "Data1" else settings.data2_points
    positions, colors, labels = load_dataset(task.dataset, task.scale, n_points, settings.data_seed)
    seed = 1000 * task.trial + 1  # same seed for every method/scale of one trial
    model = make_model(task.method, settings.max_nodes, seed)
    started = time.perf_counter()
    model.fit(positions, colors, n_steps=settings.steps)
    learn_seconds = time.perf_counter() - started

    error = model.quantization_error(positions, colors)
    winners = model.predict(positions)
    result: dict[str, Any] = {
        "method": task.method,
        "dataset": task.dataset,
        "scale": task.scale,
        "trial": task.trial,
        "seed": seed,
        "nodes": int(model.n_nodes_),
        "steps": int(model.n_steps_),
        "learn_seconds": learn_seconds,
        "qe_pos": float(error["pos"]),
        "qe_col": float(error.get("col", math.nan)),
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
        col_labels = np.asarray(model.clusters("col", min_size=settings.min_cluster_size))
        centre_errors = cluster_centre_errors(
            model.positions_, col_labels, data1_centres(task.scale)
        )
        result["centre_errors"] = dict(zip(RECTANGLES, map(float, centre_errors), strict=True))
    if task.dataset == "Data1":
        # the clustering that should find the rectangles: GNG-DT's colour topology, else the one
        main = "col" if task.method == "GNG-DT" else "pos"
        result["rectangles_separated"] = separates_regions(
            labels, topology["labels"][main][winners], len(RECTANGLES)
        )
    if task.keep_topology:
        result["topology"] = topology
    return result


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
    from gngdt_core import DATA1_CENTRES

    return scale * np.asarray(DATA1_CENTRES, dtype=np.float64)


def build_tasks(settings: PaperSettings) -> list[TrialTask]:
    """Every (dataset, scale, method, trial) run; trial 0 keeps its topology for the drawings.

    Data2 runs come first so the slowest work starts early and the pool ends evenly.
    """
    return [
        TrialTask(method, dataset, scale, trial, settings, keep_topology=trial == 0)
        for dataset in sorted(settings.datasets, reverse=True)
        for scale in settings.scales
        for trial in range(settings.trials)
        for method in settings.methods
    ]


def run_trials(
    tasks: Sequence[TrialTask],
    workers: int,
    on_done: Callable[[dict[str, Any]], None] | None = None,
) -> list[dict[str, Any]]:
    """Run ``tasks`` on ``workers`` processes (in this process when 1); results in task order."""
    results: list[dict[str, Any] | None] = [None] * len(tasks)
    if workers <= 1:
        for index, task in enumerate(tasks):
            results[index] = run_trial(task)
            if on_done:
                on_done(results[index])
        return results  # type: ignore[return-value]
    with ProcessPoolExecutor(max_workers=workers) as pool:
        futures = {pool.submit(run_trial, task): index for index, task in enumerate(tasks)}
        for future in as_completed(futures):
            results[futures[future]] = future.result()
            if on_done:
                on_done(results[futures[future]])
    return results  # type: ignore[return-value]


def _select(results: Iterable[dict[str, Any]], **where: Any) -> list[dict[str, Any]]:
    return [r for r in results if all(r[k] == v for k, v in where.items())]


def summarise(results: list[dict[str, Any]], settings: PaperSettings) -> dict[str, Any]:
    """Aggregate trials into the tables: mean/std per cell beside the published value."""
    tables: dict[str, Any] = {
        "table2": {},
        "table3": {},
        "figure10": {},
        "clusters": {},
        "ari": {},
        "table4": {},
        "rectangles_separated": {},
    }
    for dataset in settings.datasets:
        for key in ("table2", "table3", "figure10", "clusters", "ari"):
            tables[key][dataset] = {}
        for method in settings.methods:
            for key in ("table2", "table3", "figure10", "clusters", "ari"):
                tables[key][dataset][method] = {}
            for scale in settings.scales:
                runs = _select(results, dataset=dataset, method=method, scale=scale)
                if not runs:
                    continue
                published2 = PAPER_TABLE2[dataset][method].get(scale)
                published3 = PAPER_TABLE3[dataset][method].get(scale)
                tables["table2"][dataset][method][scale] = {
                    "ours": mean_std(r["qe_pos"] for r in runs),
                    "paper": _published(published2),
                }
                tables["table3"][dataset][method][scale] = {
                    "ours": mean_std(r["qe_col"] for r in runs),
                    "paper": _published(published3),
                }
                tables["figure10"][dataset][method][scale] = {
                    "ours": mean_std(r["qe_pos"] / scale for r in runs),
                    "paper": None if published2 is None else published2[0] / scale,
                }
                tables["clusters"][dataset][method][scale] = {
                    name: {
                        "per_trial": [r["clusters"][name] for r in runs],
                        "per_trial_all_sizes": [r["clusters_all"][name] for r in runs],
                        "stats": mean_std(r["clusters"][name] for r in runs),
                    }
                    for name in runs[0]["clusters"]
                }
                tables["ari"][dataset][method][scale] = {
                    name: mean_std(r["ari"][name] for r in runs) for name in runs[0]["ari"]
                }
    for scale in settings.scales:
        runs = _select(results, dataset="Data1", method="GNG-DT", scale=scale)
        if not runs:
            continue
        tables["table4"][scale] = {
            rectangle: {
                "ours": mean_std(r["centre_errors"][rectangle] for r in runs),
                "paper": _published(PAPER_TABLE4[rectangle].get(scale)),
            }
            for rectangle in RECTANGLES
        }
    for method in settings.methods:
        tables["rectangles_separated"][method] = {}
        for scale in settings.scales:
            runs = _select(results, dataset="Data1", method=method, scale=scale)
            if runs:
                tables["rectangles_separated"][method][scale] = {
                    "trials": len(runs),
                    "separated": sum(r["rectangles_separated"] for r in runs),
                }
    return tables


def _published(cell: Cell | None) -> dict[str, float] | None:
    return None if cell is None else {"mean": cell[0], "std": cell[1]}


def findings(tables: dict[str, Any], settings: PaperSettings) -> dict[str, Any]:
    """The paper's claims checked against our numbers (each with ``holds`` and the evidence)."""
    checks: dict[str, Any] = {}
    for dataset, by_method in tables["figure10"].items():
        cells = by_method.get("GNG-DT", {})
        means = [c["ours"]["mean"] for c in cells.values() if c["ours"]["n"]]
        if len(means) >= 2:
            centre = float(np.mean(means))
            deviation = max(abs(m / centre - 1.0) for m in means)
            checks[f"{dataset}: GNG-DT position error / scl flat across scales (±10 %)"] = {
                "holds": bool(deviation <= 0.10),
                "evidence": f"r_pos/scl within ±{deviation:.1%} of its mean over scales",
            }
        for scale in settings.scales:
            ours = {
                m: tables["table2"][dataset][m][scale]["ours"]["mean"]
                for m in settings.methods
                if scale in tables["table2"][dataset].get(m, {})
            }
            if "GNG-DT" not in ours or len(ours) < 2:
                continue
            others = {m: v for m, v in ours.items() if m != "GNG-DT"}
            check = {
                "holds": bool(all(ours["GNG-DT"] < v for v in others.values())),
                "evidence": ", ".join(f"{m} {v:.4g}" for m, v in ours.items()),
            }
            published = {m: PAPER_TABLE2[dataset][m].get(scale) for m in settings.methods}
            if all(value is not None for value in published.values()):  # a scale the paper has
                check["paper"] = min(published, key=lambda m: published[m][0]) == "GNG-DT"
            checks[f"{dataset} scl={scale:g}: GNG-DT has the lowest position error"] = check
    for dataset, by_method in tables["figure10"].items():
        for method in ("GNG", "GNG-W"):
            cells = by_method.get(method, {})
            if len(cells) < 2:
                continue
            smallest, largest = min(cells), max(cells)
            growth = cells[smallest]["ours"]["mean"] / cells[largest]["ours"]["mean"]
            paper = PAPER_TABLE2[dataset][method]
            evidence = f"r_pos/scl at scl={smallest:g} is {growth:.3f} x that at scl={largest:g}"
            if smallest in paper and largest in paper:
                paper_growth = (paper[smallest][0] / smallest) / (paper[largest][0] / largest)
                evidence += f" (paper: {paper_growth:.2f} x)"
            checks[f"{dataset}: {method}'s position error / scl grows as scl shrinks"] = {
                "holds": bool(growth > 1.0),
                "evidence": evidence,
            }
    data2_clusters = tables["clusters"].get("Data2", {}).get("GNG-DT", {})
    for scale, clusterings in data2_clusters.items():
        modes = {name: _mode(cell["per_trial"]) for name, cell in clusterings.items()}
        checks[f"Data2 scl={scale:g}: GNG-DT cluster counts as in Figure 11"] = {
            "holds": modes == PAPER_FIGURE11_CLUSTERS,
            "evidence": "most frequent count per topology: "
            + ", ".join(
                f"C^{n} {modes[n]} (paper {PAPER_FIGURE11_CLUSTERS.get(n)})" for n in modes
            ),
        }
    for method, by_scale in tables["rectangles_separated"].items():
        topology = "colour topology" if method == "GNG-DT" else "topology"
        for scale, counts in by_scale.items():
            separated, trials = counts["separated"], counts["trials"]
            evidence = (
                f"{separated}/{trials} trials with exactly 4 clusters "
                f"(≥ {settings.min_cluster_size} nodes), each ≥ 90 % one rectangle"
            )
            if method == "GNG-DT":
                claim = f"Data1 scl={scale:g}: GNG-DT {topology} separates the four rectangles"
                checks[claim] = {"holds": separated == trials, "evidence": evidence}
            else:
                claim = (
                    f"Data1 scl={scale:g}: {method}'s {topology} "
                    "does not separate the four rectangles"
                )
                checks[claim] = {"holds": separated == 0, "evidence": evidence}
    return checks


def _mode(values: list[int]) -> int:
    numbers, counts = np.unique(np.asarray(values), return_counts=True)
    return int(numbers[np.argmax(counts)])


def differences(tables: dict[str, Any]) -> list[dict[str, Any]]:
    """Every cell of Tables 2-3 whose mean differs from the published one by more than 10 %."""
    rows = []
    for table in ("table2", "table3"):
        for dataset, by_method in tables[table].items():
            for method, by_scale in by_method.items():
                for scale, cell in by_scale.items():
                    paper, ours = cell["paper"], cell["ours"]
                    if paper is None or not ours["n"] or paper["mean"] == 0:
                        continue
                    ratio = ours["mean"] / paper["mean"]
                    if abs(ratio - 1.0) > 0.10:
                        rows.append(
                            {
                                "table": table,
                                "dataset": dataset,
                                "method": method,
                                "scale": scale,
                                "ours": ours["mean"],
                                "paper": paper["mean"],
                                "ratio": ratio,
                            }
                        )
    return rows


def run_paper(
    settings: PaperSettings, out_dir: str | Path, progress: bool = True
) -> dict[str, Any]:
    """Run the whole experiment and write ``paper.md``, ``paper.json`` and PNGs into ``out_dir``."""
    from services.evaluation.progress import ProgressBar

    out_dir = Path(out_dir)
    tasks = build_tasks(settings)
    bar = ProgressBar(len(tasks), label="runs") if progress else None
    started = time.perf_counter()
    workers = min(settings.workers, len(tasks))
    log.info("eval paper: %d runs on %d worker(s)", len(tasks), workers)
    results = run_trials(tasks, workers, on_done=(lambda _r: bar.advance()) if bar else None)
    wall_seconds = time.perf_counter() - started
    if bar:
        bar.close()

    topologies = {
        (r["dataset"], r["method"], r["scale"]): r.pop("topology")
        for r in results
        if "topology" in r
    }
    tables = summarise(results, settings)
    checks = findings(tables, settings)
    diffs = differences(tables)
    plots = _write_plots(tables, topologies, settings, out_dir)
    data = {
        "settings": asdict(settings),
        "parameters": {
            "table1": PAPER_PARAMETERS,
            "gngdt": GNGDT_THRESHOLDS,
            "gngw": GNGW_WEIGHTS,
        },
        "wall_seconds": wall_seconds,
        "cpu_seconds_learning": sum(r["learn_seconds"] for r in results),
        "tables": tables,
        "findings": checks,
        "differences": diffs,
        "trials": results,
        "plots": [p.name for p in plots],
    }
    markdown = render_markdown(data, settings, plots)
    write_report(out_dir, "paper", markdown, data)
    return data


def _write_plots(
    tables: dict[str, Any],
    topologies: dict[tuple[str, str, float], dict[str, Any]],
    settings: PaperSettings,
    out_dir: Path,
) -> list[Path]:
    from services.evaluation.plots import TopologyPanel, plot_scale_curves, plot_topology_grid

    paths = []
    for dataset in settings.datasets:
        measured = {
            method: {s: (c["ours"]["mean"], c["ours"]["std"]) for s, c in cells.items()}
            for method, cells in tables["figure10"][dataset].items()
        }
        published = {
            method: {s: c["paper"] for s, c in cells.items() if c["paper"] is not None}
            for method, cells in tables["figure10"][dataset].items()
        }
        paths.append(
            plot_scale_curves(
                measured,
                published,
                out_dir / f"figure10_{dataset.lower()}.png",
                title=f"Figure 10 — {dataset}: position error / scl",
                ylabel="r_pos / scl",
            )
        )

        rows = []
        for scale in settings.scales:
            row: list[TopologyPanel | None] = []
            for method in settings.methods:
                topology = topologies.get((dataset, method, scale))
                if topology is None:
                    continue
                names = list(topology["labels"]) if method == "GNG-DT" else ["pos"]
                for name in names:
                    title = f"{method}" + (f" (C^{name})" if method == "GNG-DT" else "")
                    row.append(
                        TopologyPanel(
                            title=f"{title}, scl={scale:g}",
                            positions=np.asarray(topology["positions"]),
                            edges=topology["edges"][name],
                            labels=topology["labels"][name],
                        )
                    )
            if row:
                rows.append(row)
        if rows:
            figure = "Figure 8" if dataset == "Data1" else "Figure 9"
            paths.append(
                plot_topology_grid(
                    rows,
                    out_dir / f"topologies_{dataset.lower()}.png",
                    title=f"{figure} — {dataset}: topologies of trial 0, nodes coloured by cluster",
                )
            )
    return paths


def render_markdown(data: dict[str, Any], settings: PaperSettings, plots: list[Path]) -> str:
    """The Markdown report: settings, Tables 2-4 beside the paper, Figure 10, clusters, findings."""
    tables = data["tables"]
    parts = [
        "# GNG-DT paper reproduction — simulation experiment (Section 3.1)",
        f"{settings.trials} trial(s) per cell; wall time {data['wall_seconds']:.1f} s on "
        f"{settings.workers} worker process(es).",
        "## Settings",
        "Paper parameters (Table 1): "
        + ", ".join(f"{k.rstrip('_')}={v:g}" for k, v in PAPER_PARAMETERS.items())
        + f", τ_col={GNGDT_THRESHOLDS['tau_col']:g}, τ_nor={GNGDT_THRESHOLDS['tau_nor']:g}; "
        f"GNG-W weights w_pos={GNGW_WEIGHTS['w_pos']:g}, w_col={GNGW_WEIGHTS['w_col']:g}.",
        "**Node budget and stopping rule (not given in the paper; ours):** every run learns "
        f"exactly {settings.steps:,} steps (samples drawn in random order from the whole data set) "
        f"with at most {settings.max_nodes} nodes (one node inserted every λ steps until the "
        "budget is reached; adaptation continues). "
        f"Data1 has {settings.data1_points:,} points, Data2 {settings.data2_points:,}; "
        f"the point clouds are generated once (seed {settings.data_seed}) and each trial uses its "
        "own sampling seed (the same for the three methods). Quantization errors (eq. 17) are "
        "measured on every point of the data set after learning. Clusters are counted with at "
        f"least {settings.min_cluster_size} nodes (smaller ones are the isolated boundary nodes "
        "the paper mentions).",
    ]
    for number, key, quantity in ((2, "table2", "position"), (3, "table3", "colour")):
        parts.append(f"## Table {number} — quantization error of {quantity} (ours vs paper)")
        for dataset in settings.datasets:
            parts.append(_comparison_table(tables[key][dataset], dataset, settings))
    if tables["table4"]:
        parts.append("## Table 4 — GNG-DT cluster-centre error e_i of C^col on Data1")
        rows = [
            [f"scl = {scale:g}"]
            + [
                f"{format_mean_std(cells[r]['ours'])} ({format_mean_std(cells[r]['paper'])})"
                for r in RECTANGLES
            ]
            for scale, cells in tables["table4"].items()
        ]
        parts.append("Each cell: ours (paper). The paper's table has no value for C2 at scl=0.1.")
        parts.append(markdown_table(["", *RECTANGLES], rows))
    parts.append("## Figure 10 — position error / scl against scale")
    parts.extend(f"![{p.stem}]({p.name})" for p in plots if p.stem.startswith("figure10"))
    for dataset in settings.datasets:
        rows = [
            [method]
            + [
                format_mean_std(tables["figure10"][dataset][method].get(s, {}).get("ours"))
                for s in settings.scales
            ]
            for method in settings.methods
        ]
        parts.append(
            f"{dataset}, r_pos / scl:\n\n"
            + markdown_table(["method", *(f"scl={s:g}" for s in settings.scales)], rows)
        )
    parts.append("## Topologies (Figures 8 and 9)")
    parts.extend(f"![{p.stem}]({p.name})" for p in plots if p.stem.startswith("topologies"))
    parts.append("## Clusters per topology (per trial, ≥ min size) and ARI against ground truth")
    for dataset in settings.datasets:
        rows = []
        for method in settings.methods:
            for scale in settings.scales:
                clusters = tables["clusters"][dataset][method].get(scale, {})
                for name, cell in clusters.items():
                    rows.append(
                        [
                            method,
                            f"{scale:g}",
                            f"C^{name}",
                            format_mean_std(cell["stats"], 2),
                            ", ".join(map(str, cell["per_trial"])),
                            format_mean_std(tables["ari"][dataset][method][scale][name]),
                        ]
                    )
        parts.append(
            f"### {dataset}\n\n"
            + markdown_table(
                ["method", "scl", "topology", "clusters", "per trial", "ARI (points)"], rows
            )
        )
    parts.append("## The paper's findings, checked")
    parts.append(
        markdown_table(
            ["claim", "in the paper", "here", "evidence"],
            [
                [
                    claim,
                    "yes" if c.get("paper", True) else "no",
                    "yes" if c["holds"] else "**no**",
                    c["evidence"],
                ]
                for claim, c in data["findings"].items()
            ],
        )
    )
    parts.append(_differences_text(data["differences"], settings))
    return "\n\n".join(parts)


def _comparison_table(by_method: dict[str, Any], dataset: str, settings: PaperSettings) -> str:
    headers = [dataset]
    for method in settings.methods:
        headers += [f"{method} (ours)", f"{method} (paper)"]
    rows = []
    for scale in settings.scales:
        row = [f"scl = {scale:g}"]
        for method in settings.methods:
            cell = by_method.get(method, {}).get(scale)
            row += [format_mean_std(cell and cell["ours"]), format_mean_std(cell and cell["paper"])]
        rows.append(row)
    return markdown_table(headers, rows)


def _differences_text(rows: list[dict[str, Any]], settings: PaperSettings) -> str:
    lines = ["## Where our numbers differ from the paper's, and why we believe they do"]
    if not rows:
        lines.append("Every cell of Tables 2 and 3 is within 10 % of the published mean.")
    else:
        lines.append(
            f"{len(rows)} cell(s) of Tables 2-3 differ from the published mean by more than 10 %:"
        )
        lines.append(
            markdown_table(
                ["table", "data", "method", "scl", "ours", "paper", "ours/paper"],
                [
                    [
                        r["table"],
                        r["dataset"],
                        r["method"],
                        f"{r['scale']:g}",
                        format_number(r["ours"], 4),
                        format_number(r["paper"], 4),
                        format_number(r["ratio"], 2),
                    ]
                    for r in rows
                ],
            )
        )
    lines.append(
        "Why we believe they differ:\n\n"
        "- **Node budget and learning length are not published.** The position error of a "
        "quantizer falls roughly as (nodes)^(-1/d) on a d-dimensional surface, so a different "
        f"node count shifts every position cell by the same factor. We used {settings.max_nodes} "
        f"nodes and {settings.steps:,} steps; a constant ours/paper ratio across scales for "
        "GNG-DT is this effect, not a change in behaviour.\n"
        "- **Data2's geometry is reconstructed** from the paper's one-sentence description and "
        "Figure 7b (dimensions, colours and the share of points on each part are ours), so Data2's "
        "absolute errors, colour errors especially, are not comparable cell by cell; the "
        "comparisons between methods and across scales are.\n"
        "- **Colours are flat in our data sets** (Data1: pure red and pure green; Data2: one "
        "colour per part), so inside one region the colour part of GNG's and GNG-W's distance is "
        "zero and their winner search is decided by position alone. That is why GNG and GNG-W "
        "lose far less position accuracy at small scl here than in the paper (Figure 10's trend "
        "keeps its direction but shrinks); we believe the paper's data carried colour variation "
        "within each region, which then dominates the distance once positions are small. "
        "Flat colours also explain our GNG-DT colour errors: they come only from nodes on a "
        "colour boundary, whose learned colour is a mixture.\n"
        "- **Data2's cluster counts (Figure 11)** depend on the reconstructed geometry and on "
        "how τ_nor meets the cylinder's curvature at the node density used: where the C^nor "
        "count falls short, look at the C^nor drawings above — nodes on the cylinder's curved "
        "side whose neighbours' normals differ by more than τ_nor end up in clusters below the "
        "minimum size (grey) and are not counted.\n"
        "- The paper's std values of 0.000 at scl = 0.01 are rounding of small numbers."
    )
    return "\n\n".join(lines)
