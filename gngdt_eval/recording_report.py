"""The `gngdt eval recording` report: its Markdown and its PNG plots.

The Markdown is rendered from the report's data alone (what ``recording.json`` holds, settings
included), so it can be written again from a saved report; the plots need the replays' models.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from gngdt.core.clustering import COL, POS
from gngdt.eval.paper_methods import clusterings_of
from gngdt.eval.report import format_mean_std, format_number, markdown_table


def write_plots(
    runs: list[dict[str, Any]],
    refs: dict[str, Any],
    summary: dict[str, Any],
    path: Path,
    out_dir: Path,
    min_cluster_size: int,
    ghost_distance_m: float,
) -> list[Path]:
    """Per-frame errors and nodes, the metrics over time, GNG-DT's ARI (with labels) and the
    last-frame topologies of trial 0, as PNGs in ``out_dir``."""
    methods = list(summary)
    plots = [
        _plot_curves(runs, refs, summary, path, out_dir),
        _plot_over_time(runs, methods, path, out_dir, ghost_distance_m),
    ]
    ari = _plot_ari(runs, path, out_dir)
    if ari is not None:
        plots.append(ari)
    topologies = _plot_topologies(runs, path, out_dir, min_cluster_size)
    if topologies is not None:
        plots.append(topologies)
    return plots


def _mean_curve(runs: list[dict[str, Any]], method: str, key: str,
                group: str | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(frames (T,), mean over trials (T,)) of a per-frame figure (``frame[group][key]`` with
    a group; NaN where a frame lacks it)."""
    chosen = [r["frames"] for r in runs if r["method"] == method]
    frames = np.array([f["frame"] for f in chosen[0]])
    length = min(len(c) for c in chosen)

    def value(frame: dict[str, Any]) -> float:
        holder = frame if group is None else frame[group]
        return float(holder.get(key, np.nan))

    values = np.array([[value(f) for f in c[:length]] for c in chosen], dtype=np.float64)
    return frames[:length], values.mean(axis=0)


def _plot_curves(runs: list[dict[str, Any]], refs: dict[str, Any], summary: dict[str, Any],
                 path: Path, out_dir: Path) -> Path:
    """Position and colour error and nodes per frame, per method, beside the last frame's
    k-means and voxel grid at GNG-DT's node count."""
    from gngdt.eval.plots import plot_method_curves

    methods = list(summary)
    curves = {
        "position error (m)": {m: _mean_curve(runs, m, "qe_pos") for m in methods},
        "colour error (0-255)": {m: _mean_curve(runs, m, "qe_col") for m in methods},
        "nodes": {m: _mean_curve(runs, m, "nodes") for m in methods},
    }
    lines: dict[str, dict[str, float]] = {"position error (m)": {}, "colour error (0-255)": {}}
    if "GNG-DT" in summary:
        nodes = round(summary["GNG-DT"]["nodes"]["mean"])
        reference = refs["by_nodes"].get(nodes)
        if reference:
            for name, label in (("kmeans", "k-means"), ("voxel_grid", "voxel grid")):
                lines["position error (m)"][f"{label}, {nodes} (last frame)"] = reference[name][
                    "qe"
                ][POS]
                lines["colour error (0-255)"][f"{label}, {nodes} (last frame)"] = reference[name][
                    "qe"
                ][COL]
    return plot_method_curves(
        curves,
        out_dir / "recording_curves.png",
        title=f"{path.name}: per-frame errors and nodes",
        references=lines,
    )


def _plot_over_time(runs: list[dict[str, Any]], methods: list[str], path: Path,
                    out_dir: Path, ghost_distance_m: float) -> Path:
    """Ghost share, nodes, world error / k-means and old-place nodes per frame, per method."""
    from gngdt.eval.plots import plot_method_curves

    def curves(key: str, group: str | None = "dynamics") -> dict[str, Any]:
        result = {m: _mean_curve(runs, m, key, group) for m in methods}
        return {m: (x, y) for m, (x, y) in result.items() if np.isfinite(y).any()}

    quantities = {
        f"ghost share (> {ghost_distance_m * 100:g} cm from the frame)": curves("ghost_share"),
        "nodes": curves("nodes", None),
    }
    lines: dict[str, dict[str, float]] = {next(iter(quantities)): {"target 2 %": 0.02}}
    ratio = curves("world_ratio_to_kmeans")
    if ratio:
        quantities["position error / k-means, world sample"] = {
            m: (x[np.isfinite(y)], y[np.isfinite(y)]) for m, (x, y) in ratio.items()}
        lines["position error / k-means, world sample"] = {"target 1.2": 1.2}
    kept = curves("out_of_view_nodes")
    if kept:
        quantities["out-of-view nodes on the world seen"] = kept
    gngdt = [r for r in runs if r["method"] == "GNG-DT"]
    for name in gngdt[0]["changes"] if gngdt else ():
        quantities[f"old-place nodes of {name} (GNG-DT)"] = {
            "GNG-DT": _mean_curve(runs, "GNG-DT", f"old_place_nodes/{name}", "dynamics")}
    return plot_method_curves(quantities, out_dir / "recording_over_time.png",
                              title=f"{path.name}: over time", references=lines)


def _plot_ari(runs: list[dict[str, Any]], path: Path, out_dir: Path) -> Path | None:
    """GNG-DT's adjusted Rand index per clustering and frame, trial 0; None without labels."""
    from gngdt.eval.plots import plot_method_curves

    gngdt_runs = [r for r in runs if r["method"] == "GNG-DT"]
    if not gngdt_runs or "ari" not in gngdt_runs[0]["frames"][0]:
        return None
    names = list(gngdt_runs[0]["frames"][0]["ari"])
    ari_curves = {
        "ARI per clustering (GNG-DT)": {
            f"C^{n}": (
                np.array([f["frame"] for f in gngdt_runs[0]["frames"]]),
                np.array([f["ari"].get(n, np.nan) for f in gngdt_runs[0]["frames"]]),
            )
            for n in names
        }
    }
    return plot_method_curves(
        ari_curves,
        out_dir / "recording_ari.png",
        title=f"{path.name}: adjusted Rand index, trial 0",
    )


def _plot_topologies(runs: list[dict[str, Any]], path: Path, out_dir: Path,
                     min_cluster_size: int) -> Path | None:
    """Trial 0's last-frame topologies, nodes coloured by cluster, four per row."""
    from gngdt.eval.plots import TopologyPanel, plot_topology_grid

    panels = []
    for run in (r for r in runs if r["trial"] == 0):
        model = run["model"]
        for props in clusterings_of(run["method"], 3):
            name = "+".join(props)
            panels.append(
                TopologyPanel(
                    title=f"{run['method']}" + (f" C^{name}" if run["method"] == "GNG-DT" else ""),
                    positions=np.asarray(model.positions_),
                    edges=model.edges(*props),
                    camera_frame=True,
                    labels=np.asarray(model.clusters(*props, min_size=min_cluster_size)),
                )
            )
    if not panels:
        return None
    rows = [panels[i : i + 4] for i in range(0, len(panels), 4)]
    return plot_topology_grid(
        rows,
        out_dir / "recording_topologies.png",
        title=f"{path.name}: last-frame topologies, by cluster",
    )


def render_markdown(data: dict[str, Any], plots: list[Path]) -> str:
    """The recording report: final figures per method, references, per-frame table, plots.

    data: what ``recording.json`` holds (``settings`` as a dict, ``summary``, ``references``,
    ``runs``, ...).
    """
    settings = data["settings"]
    parts = [
        f"# Recording evaluation — `{Path(data['recording']).name}`",
        "Replayed offline frame by frame: GNG-DT through the learner's own per-frame policy "
        "(`gngdt.core.learner.frame_learner.FrameLearner`, as `gngdt learn` runs it), "
        "GNG and GNG-W "
        f"with `partial_fit(points, colors, n_steps={settings['samples_per_frame']:,})` per "
        f"frame; node budget {settings['max_nodes'] or 'the learner’s'}, "
        f"{settings['trials']} trial(s) per method, "
        "paper parameters (Table 1). Errors (eq. 17) are measured on each frame's own points "
        "after learning it. Clusters count topologies' connected components of at least "
        f"{settings['min_cluster_size']} nodes. Wall time {data['wall_seconds']:.1f} s.",
        _settling_note(settings),
        "## Last frame, per method (mean ± std over trials)",
        _last_frame_table(data),
        *_identity_section(data["summary"], settings),
        *_references_section(data["references"]),
        *_over_time_section(data),
        "## Per frame (trial 0)",
        *(f"### {run['method']}\n\n" + _per_frame_table(run, data["labelled"])
          for run in data["runs"] if run["trial"] == 0),
        "## Plots",
        *(f"![{p.stem}]({p.name})" for p in plots),
    ]
    return "\n\n".join(parts)


def _settling_note(settings: dict[str, Any]) -> str:
    """Why the last row may differ from what `gngdt run` shows at the end of a stream."""
    if settings.get("settle"):
        return ("GNG-DT's last row is the network after settling on the last frame, as `gngdt "
                "run`'s learner does at the end of a stream (marked *settled*).")
    return ("`gngdt run`'s learner also learns the stream's last frame on until the network "
            "settles (node budget reached, error steady); this replay does not (`--settle` "
            "does), so on a short recording it ends with fewer nodes than `gngdt run`.")


def _last_frame_table(data: dict[str, Any]) -> str:
    """Per method: nodes, errors (and their ratio to the references), clusters, ARI."""
    headers = [
        "method",
        "nodes",
        "position error (m)",
        "colour error",
        "÷ k-means (pos)",
        "÷ voxel grid (pos)",
        "clusters",
    ]
    if data["labelled"]:
        headers.append("ARI")
    rows = []
    for method, entry in data["summary"].items():
        row = [
            method,
            format_mean_std(entry["nodes"], 0),
            format_mean_std(entry["qe_pos"], 4),
            format_mean_std(entry["qe_col"], 2),
            format_number(entry.get("ratio_to_kmeans_pos"), 2),
            format_number(entry.get("ratio_to_voxel_grid_pos"), 2),
            ", ".join(f"C^{n}: {s['mean']:.1f}" for n, s in entry["clusters"].items()),
        ]
        if data["labelled"]:
            row.append(", ".join(f"C^{n}: {s['mean']:.3f}" for n, s in entry["ari"].items()))
        rows.append(row)
    return markdown_table(headers, rows)


def _identity_section(summary: dict[str, Any], settings: dict[str, Any]) -> list[str]:
    """Persistent cluster ids: tracks kept, ids kept and switched, per method and clustering."""
    text = (
        "Each cluster keeps an id from frame to frame by node membership "
        "(`gngdt.core.objects.ids`); objects are the clusters of at least "
        f"{settings['min_cluster_size']} nodes seen in {settings['object_confirm_frames']} "
        "frame(s) in a row, as the learner publishes them. *Tracks kept*: share of the objects "
        "of a frame whose id is still an object in the next. With ground truth, each segment is "
        "represented by the object most of its points fall in (when it covers at least half of "
        "them); an *id switch* is a segment represented by another id than the last time, *id "
        "kept* the share of frame-to-frame comparisons without one. Mean ± std over trials; "
        "switches summed.")
    rows = [
        [method, name, format_mean_std(score["tracks_kept"], 3),
         format_mean_std(score["id_kept"], 3), score["id_switches"], score["id_comparisons"]]
        for method, entry in summary.items() for name, score in entry["identity"].items()
    ]
    return ["## Object identity (persistent cluster ids, as the learner publishes them)", text,
            markdown_table(["method", "clustering", "tracks kept", "id kept", "id switches",
                            "comparisons"], rows)]


def _references_section(refs: dict[str, Any]) -> list[str]:
    """k-means and the voxel grid at each node count, and DBSCAN, on the last frame."""
    rows = []
    for nodes, ref in refs["by_nodes"].items():
        rows.append([
            f"k-means, {nodes} centres",
            format_number(ref["kmeans"]["qe"][POS], 4),
            format_number(ref["kmeans"]["qe"][COL], 2),
            f"fitted on {int(ref['kmeans']['fit_points']):,} points",
        ])
        rows.append([
            f"voxel grid, {int(ref['voxel_grid']['points'])} points",
            format_number(ref["voxel_grid"]["qe"][POS], 4),
            format_number(ref["voxel_grid"]["qe"][COL], 2),
            f"voxel {ref['voxel_grid']['voxel_size'] * 1000:.1f} mm",
        ])
    parts = [f"## References on the last frame's {refs['points']:,} points",
             markdown_table(["reference", "position error (m)", "colour error", "note"], rows)]
    if "dbscan" in refs:
        dbscan = refs["dbscan"]
        text = (
            f"DBSCAN of the raw positions ({dbscan['points']:,} points, eps "
            f"{dbscan['eps_m'] * 1000:.1f} mm, min_samples {dbscan['min_samples']}): "
            f"{dbscan['clusters']} clusters, {dbscan['noise_fraction']:.1%} noise"
        )
        if "ari" in dbscan:
            text += f", ARI {dbscan['ari']:.3f} (noise counted as one cluster)"
            if "gngdt_ari_same_points" in dbscan:
                text += "; GNG-DT on the same points: " + ", ".join(
                    f"C^{n} {v:.3f}" for n, v in dbscan["gngdt_ari_same_points"].items()
                )
        parts.append(text + ".")
    return parts


def _over_time_section(data: dict[str, Any]) -> list[str]:
    """The "Over time" section: definitions, one row per method, then the changed objects."""
    parts = ["## Over time", _over_time_text(data["settings"], data["posed"]),
             _over_time_table(data["summary"], data["posed"])]
    change_rows = [
        [method, name, change["kind"], change["settled_frame"], change["old_place_nodes_at_change"],
         format_mean_std(change["frames_until_gone"], 1) if change["frames_until_gone"]
         else f"not within the run ({change['gone_in_trials']}/{data['settings']['trials']} "
              "trials)"]
        for method, entry in data["summary"].items()
        for name, change in entry["over_time"]["changes"].items()
    ]
    if change_rows:
        parts.append(
            "Objects that changed (from the recording's scene description): once an object has "
            "vanished or finished moving, the nodes within the ghost distance of its place in "
            "the frame before its change, and farther than that from the current frame, are its "
            "old-place nodes.")
        parts.append(markdown_table(
            ["method", "object", "change", "gone / moved by frame", "old-place nodes then",
             "frames until none"], change_rows))
    return parts


def _over_time_text(settings: dict[str, Any], posed: bool) -> str:
    """What the metrics over time mean, with the settings they were measured with."""
    dyn = settings["dynamics"]
    frame = ("in the recording's fixed frame (camera poses)" if posed
             else "in the camera frame (the recording has no poses)")
    forgetting = (f"GNG-DT forgets with utility_k = {settings['utility_k']:g}"
                  if settings["utility_k"] is not None else "GNG-DT does not forget")
    forgetting += (f" and rehearses {settings['replay_share']:.0%} of each frame's steps from "
                   "earlier frames" if settings["replay_share"] else " and does not rehearse")
    text = (
        f"Learned {frame}; {forgetting}. A node is *seen* when the frame's sensor could have seen "
        "it (in view, not behind the measured surface by more than "
        f"{dyn['view_depth_margin']:.0%} of the depth) and a *ghost* when seen and farther than "
        f"{dyn['ghost_distance_m'] * 100:g} cm from every point of the frame; the ghost share is "
        "ghosts / seen nodes. The stale share is the share of all nodes farther than that from "
        "the frame's points. Steady state: the second half of the frames."
    )
    if posed:
        text += (
            f" The world sample keeps {dyn['world_sample']:,} points of every frame so far, in "
            "the fixed frame, minus those a later frame saw through; k-means with as many "
            "centres as nodes is fitted on half of it and both errors (eq. 17) are measured on "
            f"the other half, every {dyn['reference_every']} frames and on the last. Out of "
            "view: its points off the image or occluded, and the nodes the frame could not see "
            "that lie within the ghost distance of it (the map kept where the camera does not "
            "look)."
        )
    return text


def _over_time_table(summary: dict[str, Any], posed: bool) -> str:
    """Per method: steady-state ghost and stale shares, nodes, forgotten, world errors."""
    headers = ["method", "ghost share, steady (mean / max)", "stale share, steady",
               "nodes (max)", "forgotten"]
    if posed:
        headers += ["world error ÷ k-means (last)", "error out of view / in view (last, m)",
                    "out-of-view nodes (last)"]
    rows = []
    for method, entry in summary.items():
        over = entry["over_time"]
        row = [
            method,
            f"{over['ghost_share_steady']['mean']:.2%} / "
            f"{over['ghost_share_steady_max']['mean']:.2%}",
            f"{over['stale_share_steady']['mean']:.1%}",
            format_mean_std(over["nodes_max"], 0),
            format_mean_std(over["forgotten"], 0),
        ]
        if posed:
            ratio = over.get("world_ratio_to_kmeans")
            outside, inside = over.get("out_of_view_qe_pos"), over.get("in_view_qe_pos")
            kept = over.get("out_of_view_nodes")
            row += [format_mean_std(ratio, 3) if ratio else "—",
                    f"{outside['mean']:.4f} / {inside['mean']:.4f}" if outside and inside
                    else "—",
                    format_mean_std(kept, 0) if kept else "—"]
        rows.append(row)
    return markdown_table(headers, rows)


def _per_frame_table(run: dict[str, Any], labelled: bool) -> str:
    """One replay, frame by frame: points, nodes, errors, clusters, seen nodes, ghosts, ARI."""
    names = list(run["frames"][0]["clusters"])
    headers = [
        "frame",
        "points",
        "nodes",
        "pos err (m)",
        "col err",
        *(f"clusters C^{n}" for n in names),
        "seen nodes",
        "ghost share",
        "forgotten",
    ]
    if labelled:
        headers += [f"ARI C^{n}" for n in names]
    rows = []
    for f in run["frames"]:
        row = [
            f["frame"],
            f["points"],
            f["nodes"],
            format_number(f["qe_pos"], 4),
            format_number(f["qe_col"], 2),
            *(f["clusters"][n] for n in names),
            f["dynamics"]["seen_nodes"],
            f"{f['dynamics']['ghost_share']:.1%}",
            f["dynamics"]["forgotten"],
        ]
        if labelled:
            row += [format_number(f["ari"].get(n)) for n in names]
        rows.append(row)
    return markdown_table(headers, rows)
