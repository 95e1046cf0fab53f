"""Matplotlib PNGs for the evaluation reports (Agg backend, no display needed).

Every function writes one PNG and returns its path. Topology drawings follow the paper's Figures 8
and 9: nodes and edges of one topology, each node coloured by its cluster.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

#: colour of nodes in clusters below the minimum size (label -1).
_UNCLUSTERED = (0.75, 0.75, 0.75, 1.0)


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(figure, path: Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(path, dpi=110, bbox_inches="tight")
    _pyplot().close(figure)
    return path


def cluster_colours(labels: np.ndarray) -> np.ndarray:
    """(N, 4) RGBA float colours for cluster ``labels`` (N,) int; -1 is grey.

    The largest cluster gets the first colour, so the same scene looks the same across plots.
    """
    from matplotlib import colormaps

    palette = np.array(colormaps["tab10"].colors + colormaps["Dark2"].colors)
    labels = np.asarray(labels)
    colours = np.tile(np.array(_UNCLUSTERED), (labels.size, 1))
    valid = labels >= 0
    if valid.any():
        ids, inverse, counts = np.unique(labels[valid], return_inverse=True, return_counts=True)
        rank_of_id = np.empty(ids.size, dtype=np.int64)
        rank_of_id[np.argsort(-counts, kind="stable")] = np.arange(ids.size)
        colours[valid, :3] = palette[rank_of_id[inverse] % len(palette)]
    return colours


@dataclass
class TopologyPanel:
    """One drawing: node positions (N, 2|3) float, edges (E, 2) int pairs, cluster labels (N,)."""

    title: str
    positions: np.ndarray
    edges: np.ndarray
    labels: np.ndarray
    #: positions are in a camera frame (x right, y down, z forward): drawn with y up, z as depth
    camera_frame: bool = False


def plot_topology_grid(
    panels: Sequence[Sequence[TopologyPanel | None]], path: Path, title: str = ""
) -> Path:
    """A grid of topology drawings (rows x columns); 3D positions get a 3D axis; None = blank."""
    plt = _pyplot()
    n_rows = len(panels)
    n_cols = max(len(row) for row in panels)
    figure = plt.figure(figsize=(3.2 * n_cols, 3.2 * n_rows))
    for r, row in enumerate(panels):
        for c, panel in enumerate(row):
            if panel is None:
                continue
            three_d = panel.positions.shape[1] == 3
            axis = figure.add_subplot(
                n_rows, n_cols, r * n_cols + c + 1, projection="3d" if three_d else None
            )
            _draw_topology(axis, panel, three_d)
    if title:
        figure.suptitle(title)
    figure.tight_layout()
    return _save(figure, path)


def _draw_topology(axis, panel: TopologyPanel, three_d: bool) -> None:
    from matplotlib.collections import LineCollection

    from gngdt.core import cluster_count

    colours = cluster_colours(panel.labels)
    positions = np.asarray(panel.positions, dtype=np.float64)
    if panel.camera_frame:
        positions = np.column_stack([positions[:, 0], positions[:, 2], -positions[:, 1]])
    edges = np.asarray(panel.edges, dtype=np.int64).reshape(-1, 2)
    segments = positions[edges]
    edge_colours = colours[edges[:, 0]] if edges.size else np.empty((0, 4))
    if three_d:
        from mpl_toolkits.mplot3d.art3d import Line3DCollection

        if len(segments):  # matplotlib cannot autoscale an empty 3D collection
            axis.add_collection3d(Line3DCollection(segments, colors=edge_colours, linewidths=0.5))
        axis.scatter(*positions.T, c=colours, s=4, depthshade=False)
        axis.set_box_aspect(np.ptp(positions, axis=0) + 1e-12)
        axis.tick_params(labelsize=5)
        if panel.camera_frame:
            axis.set_xlabel("x (m)", fontsize=6)
            axis.set_ylabel("z, depth (m)", fontsize=6)
            axis.set_zlabel("-y, up (m)", fontsize=6)
            axis.view_init(elev=20, azim=-80)
    else:
        if len(segments):
            axis.add_collection(LineCollection(segments, colors=edge_colours, linewidths=0.5))
        axis.scatter(positions[:, 0], positions[:, 1], c=colours, s=5, zorder=2)
        axis.set_aspect("equal")
        axis.tick_params(labelsize=6)
    n_clusters = cluster_count(panel.labels)
    axis.set_title(f"{panel.title}\n{len(positions)} nodes, {n_clusters} clusters", fontsize=8)


def plot_scale_curves(
    measured: Mapping[str, Mapping[float, tuple[float, float]]],
    published: Mapping[str, Mapping[float, float]],
    path: Path,
    title: str,
    ylabel: str,
) -> Path:
    """The paper's Figure 10: a value (e.g. r_pos / scl) against scale, one line per method.

    measured: method -> {scl: (mean, std)} drawn solid with error bars;
    published: method -> {scl: value} drawn dashed (the paper's table / scl).
    """
    plt = _pyplot()
    figure, axis = plt.subplots(figsize=(5, 3.6))
    for index, (method, cells) in enumerate(measured.items()):
        colour = f"C{index}"
        scales = sorted(cells)
        means = [cells[s][0] for s in scales]
        stds = [cells[s][1] for s in scales]
        axis.errorbar(
            scales, means, yerr=stds, marker="o", color=colour, label=f"{method} (ours)", capsize=3
        )
        if method in published:
            paper_scales = sorted(published[method])
            axis.plot(
                paper_scales,
                [published[method][s] for s in paper_scales],
                linestyle="--",
                marker="x",
                color=colour,
                alpha=0.6,
                label=f"{method} (paper)",
            )
    axis.set_xscale("log")
    axis.set_xlabel("scale factor scl")
    axis.set_ylabel(ylabel)
    axis.set_title(title, fontsize=10)
    axis.grid(True, alpha=0.3)
    axis.legend(fontsize=7)
    return _save(figure, path)


def plot_metric_series(
    series: Mapping[str, tuple[np.ndarray, np.ndarray]], path: Path, title: str = ""
) -> Path:
    """Small multiples: one panel per named series (x (T,), y (T,)), shared x axis = frame."""
    plt = _pyplot()
    names = list(series)
    n_cols = min(3, max(1, len(names)))
    n_rows = max(1, math.ceil(len(names) / n_cols))
    figure, axes = plt.subplots(n_rows, n_cols, figsize=(4.2 * n_cols, 2.6 * n_rows), squeeze=False)
    for axis, name in zip(axes.flat, names, strict=False):
        x, y = series[name]
        axis.plot(x, y, marker=".", markersize=3, linewidth=1)
        axis.set_title(name, fontsize=9)
        axis.set_xlabel("frame", fontsize=8)
        axis.grid(True, alpha=0.3)
        axis.tick_params(labelsize=7)
    for axis in list(axes.flat)[len(names) :]:
        axis.axis("off")
    if title:
        figure.suptitle(title, fontsize=10)
    figure.tight_layout()
    return _save(figure, path)


def plot_method_curves(
    curves: Mapping[str, Mapping[str, tuple[np.ndarray, np.ndarray]]],
    path: Path,
    title: str = "",
    references: Mapping[str, Mapping[str, float]] | None = None,
) -> Path:
    """One panel per quantity, one line per method: curves[quantity][method] = (frames, values).

    references[quantity][name] = value draws a horizontal dotted line (e.g. the k-means error).
    """
    plt = _pyplot()
    quantities = list(curves)
    figure, axes = plt.subplots(
        1, len(quantities), figsize=(4.4 * len(quantities), 3.2), squeeze=False
    )
    for axis, quantity in zip(axes[0], quantities, strict=True):
        for index, (method, (x, y)) in enumerate(curves[quantity].items()):
            axis.plot(x, y, marker=".", markersize=4, color=f"C{index}", label=method)
        for index, (name, value) in enumerate((references or {}).get(quantity, {}).items()):
            axis.axhline(value, linestyle=":", color=f"C{index + 5}", label=name)
        axis.set_title(quantity, fontsize=9)
        axis.set_xlabel("frame", fontsize=8)
        axis.grid(True, alpha=0.3)
        axis.legend(fontsize=7)
        axis.tick_params(labelsize=7)
    if title:
        figure.suptitle(title, fontsize=10)
    figure.tight_layout()
    return _save(figure, path)


def label_image_colours(labels: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 picture of (H, W) int labels: 0 black, 1 grey (no segment /
    background), each k >= 2 a distinct, stable colour (golden-ratio hues)."""
    from matplotlib.colors import hsv_to_rgb

    labels = np.asarray(labels, dtype=np.int64)
    ids = np.arange(int(labels.max(initial=0)) + 1)
    hues = (ids * 0.618033988749895) % 1.0
    saturation = np.where(ids % 2 == 0, 0.85, 0.6)
    palette = (hsv_to_rgb(np.column_stack([hues, saturation, np.full(ids.size, 0.95)]))
               * 255).astype(np.uint8)
    palette[0] = 0
    if palette.shape[0] > 1:
        palette[1] = 150
    return palette[labels]


def plot_image_rows(
    rows: Sequence[Sequence[tuple[str, np.ndarray]]], path: Path, title: str = ""
) -> Path:
    """A grid of pictures, one row per entry: each (title, (H, W, 3) uint8 RGB image)."""
    plt = _pyplot()
    n_rows = len(rows)
    n_cols = max(len(row) for row in rows)
    figure, axes = plt.subplots(n_rows, n_cols, figsize=(3.4 * n_cols, 2.8 * n_rows),
                                squeeze=False)
    for axis_row, row in zip(axes, rows, strict=True):
        for axis, (panel_title, image) in zip(axis_row, row, strict=False):
            axis.imshow(image, interpolation="nearest")
            axis.set_title(panel_title, fontsize=8)
        for axis in axis_row:
            axis.axis("off")
    if title:
        figure.suptitle(title, fontsize=10)
    figure.tight_layout()
    return _save(figure, path)
