"""The `gngdt eval paper` report: Markdown beside the paper's tables, and its PNG figures."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from gngdt.core.clustering import POS
from gngdt.eval.paper_common import (
    GNGDT_THRESHOLDS,
    GNGW_WEIGHTS,
    PAPER_FIGURE11_CLUSTERS,
    PAPER_PARAMETERS,
    PAPER_TABLE5,
    PAPER_TABLE6,
    PAPER_WINNERS,
    RECTANGLES,
    PaperSettings,
)
from gngdt.eval.report import format_mean_std, format_number, markdown_table


def noise_label(level: float) -> str:
    return f"σ = {level:g}"


#: the paper's topology drawings: Figure 8 is Data1's, Figure 9 Data2's
TOPOLOGY_FIGURES = {"Data1": "Figure 8", "Data2": "Figure 9"}


def write_plots(
    tables: dict[str, Any],
    topologies: dict[tuple[str, str, float], dict[str, Any]],
    settings: PaperSettings,
    out_dir: Path,
) -> list[Path]:
    """Figure 10 per data set (``figure10_<data>.png``) and the topology grids of Figures 8
    (``figure8_data1.png``) and 9 (``figure9_data2.png``), for the main noise level."""
    from gngdt.eval.plots import TopologyPanel, plot_scale_curves, plot_topology_grid

    paths = []
    main = noise_label(settings.color_noise[0])
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
                title=f"Figure 10 — {dataset} ({main}): position error / scl",
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
                names = list(topology["labels"]) if method == "GNG-DT" else [POS]
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
            figure = TOPOLOGY_FIGURES.get(dataset, "Figure 9")
            paths.append(
                plot_topology_grid(
                    rows,
                    out_dir / f"{figure.lower().replace(' ', '')}_{dataset.lower()}.png",
                    title=f"{figure} — {dataset} ({main}): topologies of trial 0, nodes "
                    "coloured by cluster",
                )
            )
    return paths


def render_markdown(data: dict[str, Any], settings: PaperSettings, plots: list[Path]) -> str:
    """The whole report: settings, the colour model's fit, Tables 2-6, Figures 8-11, claims."""
    levels = data["levels"]
    main_level = settings.color_noise[0]
    main = levels[main_level]["tables"]
    learning = data["learning"]
    parts = [
        "# GNG-DT paper reproduction — simulation (Section 3.1) and RGB-D (Section 3.3) "
        "experiments",
        f"{settings.trials} trial(s) per cell; wall time {data['wall_seconds']:.1f} s on "
        f"{settings.workers} worker process(es), {data['cpu_seconds_learning']:.0f} s of it "
        "spent learning.",
        "## Settings",
        "Paper parameters (Table 1): "
        + ", ".join(f"{k.rstrip('_')}={v:g}" for k, v in PAPER_PARAMETERS.items())
        + f", τ_col={GNGDT_THRESHOLDS['tau_col']:g}, τ_nor={GNGDT_THRESHOLDS['tau_nor']:g}; "
        f"GNG-W weights w_pos={GNGW_WEIGHTS['w_pos']:g}, w_col={GNGW_WEIGHTS['w_col']:g}.",
        _protocol_text(settings, learning, main),
        "**Colour model (ours; the paper does not describe its colours):** every point takes its "
        "region's base colour plus independent Gaussian noise of standard deviation σ on each of "
        "R, G and B, clipped to 0-255 (Data1: pure red (255, 0, 0) and green (0, 255, 0); "
        "Data2: red (200, 30, 30) and brown (140, 90, 50)). Levels run: "
        + ", ".join(noise_label(level) + (" (main)" if level == main_level else "")
                    for level in settings.color_noise)
        + "; σ = 0 is flat colour inside each region.",
        f"Data1 has {settings.data1_points:,} points, Data2 {settings.data2_points:,}; the point "
        f"clouds are generated once (seed {settings.data_seed}) and trial k samples with seed "
        "1000 k + 1 for every method, scale and noise level. Quantization errors (eq. 17) are "
        "measured on every point after learning. Clusters are counted with at least "
        f"{settings.min_cluster_size} nodes (smaller ones are the isolated boundary nodes the "
        "paper mentions).",
        _fit_section(levels, settings),
    ]
    for number, key, quantity in ((2, "table2", "position"), (3, "table3", "colour")):
        for level in settings.color_noise:
            parts.append(f"## Table {number} — quantization error of {quantity}, "
                         f"{noise_label(level)} (ours vs paper)")
            for dataset in settings.datasets:
                parts.append(_comparison_table(levels[level]["tables"][key][dataset], dataset,
                                               settings))
    if main["table4"]:
        parts.append(_table4_section(levels, settings))
    parts.append("## Figure 10 — position error / scl against scale")
    parts.extend(f"![{p.stem}]({p.name})" for p in plots if p.stem.startswith("figure10"))
    for dataset in settings.datasets:
        rows = [
            [noise_label(level), method]
            + [format_mean_std(levels[level]["tables"]["figure10"][dataset][method]
                               .get(s, {}).get("ours")) for s in settings.scales]
            for level in settings.color_noise
            for method in settings.methods
        ]
        parts.append(
            f"{dataset}, r_pos / scl:\n\n"
            + markdown_table(["colour", "method", *(f"scl={s:g}" for s in settings.scales)],
                             rows)
        )
    parts.append("## Topologies (Figures 8 and 9)")
    parts.extend(f"![{p.stem}]({p.name})" for p in plots
                 if p.stem.startswith(("figure8", "figure9")))
    parts.append(_clusters_section(main, settings))
    if "Data2" in settings.datasets and "GNG-DT" in settings.methods:
        parts.append(_figure11_section(levels, settings))
    parts.append(_claims_section(levels, settings))
    if data.get("real_frames"):
        parts.append(_real_frames_section(data["real_frames"], settings))
    parts.append(_differences_text(data, settings))
    return "\n\n".join(parts)


def _protocol_text(settings: PaperSettings, learning: dict[str, Any],
                   tables: dict[str, Any]) -> str:
    if settings.stop == "budget":
        rule = (
            "every run stops when it has "
            f"{settings.max_nodes} nodes — the criterion the paper's Step 10 names (\"the number "
            "of nodes\"). A node is inserted every λ steps, so that is "
            f"{PAPER_PARAMETERS['lambda_'] * (settings.max_nodes - 2):,.0f} steps, plus λ per "
            "node deleted on the way; no run adapts past the budget."
        )
    else:
        rule = (
            f"every run learns exactly {settings.steps:,} steps with at most "
            f"{settings.max_nodes} nodes (one node inserted every λ steps until the budget is "
            "reached; adaptation continues after it)."
        )
    return (
        "**Stopping rule and node budget (not given in the paper; ours):** " + rule
        + f" Runs learned {_span(learning['steps_min'], learning['steps_max'])} steps and "
        f"ended with {_span(learning['nodes_min'], learning['nodes_max'])} nodes. "
        + _budget_text(settings, tables)
    )


#: the cell the default node budget was chosen by: GNG-DT's Data1 position error at scl = 1
BUDGET_CELL = ("table2", "Data1", "GNG-DT", 1.0)


def _budget_text(settings: PaperSettings, tables: dict[str, Any]) -> str:
    """What the node budget does to the cell it was chosen by, from this run's own figures."""
    default = PaperSettings.max_nodes
    key, dataset, method, scale = BUDGET_CELL
    cell = tables[key].get(dataset, {}).get(method, {}).get(scale) or {}
    ours, paper = (cell.get("ours") or {}).get("mean"), (cell.get("paper") or {}).get("mean")
    why = ("the default budget, {default} nodes, was chosen to put GNG-DT's Data1 position "
           "error at scl = 1 near the paper's {paper} (it does not depend on colour, so this "
           "pins the node count independently of the colour model)")
    if ours is None or paper is None or not math.isfinite(ours):
        return (why.format(default=default, paper="published value").capitalize()
                + "; this run has no such cell to check it against.")
    found = (f"With {settings.max_nodes} nodes, GNG-DT's Data1 position error at scl = 1 is "
             f"{format_number(ours)}, {ours / paper:.2f} × the paper's {format_number(paper)}")
    if settings.max_nodes == default:
        return f"{found}: {why.format(default=default, paper=format_number(paper))}."
    return (f"{found}; {why.format(default=default, paper=format_number(paper))}, and "
            f"{settings.max_nodes} is not it.")


def _span(low: int, high: int) -> str:
    return f"{low:,}" if low == high else f"{low:,}-{high:,}"


def _fit_section(levels: dict[float, Any], settings: PaperSettings) -> str:
    rows = []
    for level in settings.color_noise:
        fit = levels[level]["fit"]
        rows.append([noise_label(level), *(format_number(fit[k]) for k in
                                           ("table2", "table3", "Data1", "Data2", "all"))])
    best = min(settings.color_noise, key=lambda level: levels[level]["fit"]["all"]
               if math.isfinite(levels[level]["fit"]["all"]) else math.inf)
    return "\n\n".join([
        "## Colour model: how well each level reproduces the paper's baselines",
        "For each cell of GNG and GNG-W in Tables 2 and 3: log(ours / paper) of the cell's ratio "
        "to GNG-DT in the same row (data set, scale). The ratio cancels what the paper leaves "
        "open and shares among the three methods — the node budget, Data2's geometry, the "
        "colours' exact values — and keeps what the colour model changes: how far the "
        "baselines fall behind GNG-DT. Each column is the RMS of those logs (0 = the paper's "
        "ratios exactly; 0.1 ≈ 10 % off); the default level minimises \"all\" over a grid "
        "(gngdt_eval/README.md gives the run).",
        markdown_table(["colour", "Table 2 (position)", "Table 3 (colour)", "Data1", "Data2",
                        "all"], rows),
        f"Lowest \"all\" in this run: {noise_label(best)}.",
    ])


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


def _table4_section(levels: dict[float, Any], settings: PaperSettings) -> str:
    parts = ["## Table 4 — GNG-DT cluster-centre error e_i of C^col on Data1"]
    for level in settings.color_noise:
        tables = levels[level]["tables"]
        rows = [
            [f"scl = {scale:g}"]
            + [
                f"{format_mean_std(cells[r]['ours'])} ({format_mean_std(cells[r]['paper'])})"
                for r in RECTANGLES
            ]
            + [format_mean_std(_mean_over_rectangles(tables["table4_all_nodes"][scale]), 3),
               format_mean_std(tables["nodes_outside_colour_clusters"][scale], 1)]
            for scale, cells in tables["table4"].items()
        ]
        parts.append(f"{noise_label(level)}: each cell ours (paper); the paper's table has no "
                     "value for C2 at scl = 0.1.")
        parts.append(markdown_table(
            ["", *RECTANGLES, "e_i, every node of the rectangle", "nodes in no C^col cluster"],
            rows))
    parts.append(
        "*e_i, every node of the rectangle*: the same error with each rectangle's centre taken "
        "over all nodes lying in it, clustered or not (mean over C1-C4). It is a fraction of "
        "e_i: the network itself is centred, and e_i is the shift left by the nodes no colour "
        "cluster holds — those on the two inner colour boundaries, whose colour is a mixture "
        "(the paper's own explanation: \"as a result of the isolated nodes, the centers of "
        "clusters shifted\"). Leaving out a strip of width w along a rectangle's two inner "
        "sides moves its centroid by about w / √2, so our e_i corresponds to a strip about "
        "half a node spacing wide and the paper's smaller e_i to a narrower one; the colour "
        "noise hardly changes it (compare the levels). The paper gives nothing (node count, "
        "its exact colours) that would tell why its strip is narrower."
    )
    return "\n\n".join(parts)


def _mean_over_rectangles(cells: dict[str, dict[str, float]]) -> dict[str, float]:
    means = [cells[r]["mean"] for r in RECTANGLES]
    return {"mean": float(np.mean(means)), "std": float(np.std(means)), "n": len(means)}


def _clusters_section(tables: dict[str, Any], settings: PaperSettings) -> str:
    parts = [f"## Clusters per topology ({noise_label(settings.color_noise[0])}; per trial, "
             "≥ min size) and ARI against ground truth"]
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
    return "\n\n".join(parts)


def _figure11_section(levels: dict[float, Any], settings: PaperSettings) -> str:
    rows = []
    for level in settings.color_noise:
        clusters = levels[level]["tables"]["clusters"]["Data2"].get("GNG-DT", {})
        for scale, cells in clusters.items():
            rows.append([noise_label(level), f"{scale:g}"]
                        + [format_mean_std(cells[name]["stats"], 2) for name in
                           PAPER_FIGURE11_CLUSTERS])
    rows.append(["paper (Figure 11)", "—"] + [str(v) for v in PAPER_FIGURE11_CLUSTERS.values()])
    spread_rows = []
    tau = GNGDT_THRESHOLDS["tau_nor"]
    for scale, surfaces in levels[settings.color_noise[0]]["tables"]["normal_edges"].items():
        for surface, cell in surfaces.items():
            spread_rows.append([f"{scale:g}", surface, format_number(cell["edges"]["mean"], 1),
                                format_number(cell["median"]["mean"], 4),
                                f"{cell['below_tau']['mean']:.0%}"])
    return "\n\n".join([
        "## Figure 11 — GNG-DT's clusters on Data2",
        markdown_table(["colour", "scl", *(f"C^{n}" for n in PAPER_FIGURE11_CLUSTERS)], rows),
        f"Why C^nor has the count it has ({noise_label(settings.color_noise[0])}): for the "
        "position edges inside each surface (a node belongs to the surface most of its points "
        "lie on), the sign-invariant distance between the two nodes' normals — eq. 4 keeps a "
        f"normal edge below τ_nor = {tau:g}.",
        markdown_table(["scl", "surface", "position edges", "median normal distance",
                        "share < τ_nor"], spread_rows),
        "A surface is one normal cluster when enough of its position edges pass eq. 4. On the "
        "half cylinder (radius 40) two neighbours a node spacing apart have normals that turn "
        "by about spacing / radius radians — the median above — ten times τ_nor, so almost "
        "none of its edges pass and its nodes form no cluster of the minimum size: the "
        "cylinder would need nodes less than 40 × τ_nor = 0.8 units apart. That is why C^nor "
        "(and with it C^col+nor) falls short of the paper's counts, at every colour level; "
        "the paper's fourth normal cluster cannot come from a cylinder of this size at this "
        "node density, and the paper gives neither.",
    ])


def _claims_section(levels: dict[float, Any], settings: PaperSettings) -> str:
    claims: list[str] = []
    for level in settings.color_noise:
        claims += [c for c in levels[level]["findings"] if c not in claims]
    rows = []
    for claim in claims:
        row = [claim]
        for level in settings.color_noise:
            check = levels[level]["findings"].get(claim)
            row.append("—" if check is None else
                       f"{'yes' if check['holds'] else '**no**'}: {check['evidence']}")
        rows.append(row)
    headers = ["the paper's claim", *(f"reproduced at {noise_label(level)}?"
                                      for level in settings.color_noise)]
    return "\n\n".join(["## The paper's claims, checked", markdown_table(headers, rows)])


def _real_frames_section(real: dict[str, Any], settings: PaperSettings) -> str:
    tables = real["tables"]
    parts = [
        "## Tables 5 and 6 — real RGB-D frames (Section 3.3)",
        f"{real['trials']} trial(s) per frame and method; the simulation's parameters, node "
        "budget and stopping rule (as the paper: \"the parameters of each method use the same "
        "as the above simulation experiment\"). Every pixel with a depth in 0.1-10 m is a point "
        "(the capture service's deprojection); positions in **millimetres** (the scale on "
        "which the paper's errors of 8-13 and GNG-W's weights make sense), colours 0-255. "
        "Bold: the lowest mean of the row, as the paper marks it. Our frames are not the "
        "paper's (six Azure Kinect scenes it does not publish); the rows compare methods, not "
        "numbers across the two tables.",
    ]
    for key, number, quantity, paper in (("table5", 5, "position (mm)", PAPER_TABLE5),
                                         ("table6", 6, "colour", PAPER_TABLE6)):
        rows = []
        for frame, row in tables[key].items():
            rows.append([frame, f"{tables['points'][frame]:,}"]
                        + [_bold_if(format_mean_std(row["cells"][m]), m == row["winner"])
                           for m in settings.methods])
        parts.append(f"### Table {number} — quantization error of {quantity}, ours\n\n"
                     + markdown_table(["frame", "points", *settings.methods], rows))
        paper_rows = [[name] + [_bold_if(f"{cells[m][0]:.3f} ± {cells[m][1]:.4g}",
                                         m == PAPER_WINNERS[key][name])
                                for m in settings.methods if m in cells]
                      for name, cells in paper.items()]
        parts.append(f"Table {number} of the paper:\n\n"
                     + markdown_table(["dataset", *settings.methods], paper_rows))
    if real["findings"]:
        parts.append(markdown_table(
            ["the paper's claim (Section 3.3)", "reproduced?"],
            [[claim, f"{'yes' if c['holds'] else '**no**'}: {c['evidence']}"]
             for claim, c in real["findings"].items()]))
    return "\n\n".join(parts)


def _bold_if(text: str, bold: bool) -> str:
    return f"**{text}**" if bold else text


def _differences_text(data: dict[str, Any], settings: PaperSettings) -> str:
    rows = data["differences"]
    main = noise_label(settings.color_noise[0])
    lines = [f"## Where our numbers differ from the paper's ({main}), and why"]
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
        "Why, as far as we can establish:\n\n"
        "- **Node budget and stopping rule are not published.** The budget is pinned by GNG-DT's "
        "Data1 error at scl = 1 (see Settings); every other GNG-DT position cell follows from "
        "it, so a constant ours/paper ratio of GNG-DT's cells across scales is the geometry, "
        "not a change in behaviour.\n"
        "- **Data2's geometry is reconstructed** from one sentence and Figure 7b (dimensions, "
        "colours, the share of points on each part are ours): its absolute errors are not "
        "comparable cell by cell, only the comparisons between methods and across scales.\n"
        "- **The colours are not published either.** With flat colours (σ = 0) GNG and GNG-W "
        "choose winners by position alone inside a region and do not degrade at small scl "
        "(Figure 10 stays flat); with noise, the colour term takes over once positions are "
        "small. No single Gaussian level reproduces both tables: the baselines' position "
        "degradation (Table 2) fits a few units of noise, their colour errors relative to "
        "GNG-DT (Table 3) fit tens of units (see the fit table); the default is the level "
        "with the best fit over both.\n"
        "- **GNG-DT's Data1 colour error** comes mostly from nodes on a colour boundary, whose "
        "colour is a mixture: with pure red against pure green (360 apart) each such node "
        "costs up to 180 per point. The paper's lower figure (26) suggests less contrast "
        "between its two colours than pure red/green; we kept the colours the paper names.\n"
        "- **Table 4** and **Figure 11**: see the diagnostics under each (the nodes the colour "
        "clusters leave out; the normal turn between cylinder nodes against τ_nor).\n"
        "- The paper's std values of 0.000 at scl = 0.01 are rounding of small numbers."
    )
    return "\n\n".join(lines)
