"""How a topology is drawn: edges chained into polylines (each edge once, one class per
polyline), and what a real .rrd holds for the viewer: the nodes once with every clustering's
colours, each clustering's edges in its cluster colours, and views that pick those colours."""

from __future__ import annotations

from itertools import pairwise

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from gngdt.schemas.cluster_colors import edge_classes, edge_strips, id_colors, node_cluster_ids


def _segments(polylines: list, classes: list) -> list[tuple]:
    """(low node, high node, class) of every segment the polylines (node indices) draw."""
    drawn = []
    for points, strip_class in zip(polylines, classes, strict=True):
        assert len(points) >= 2  # a polyline draws at least one edge
        drawn += [(min(a, b), max(a, b), strip_class) for a, b in pairwise(points)]
    return sorted(drawn)


@given(st.lists(st.tuples(st.integers(0, 30), st.integers(0, 30), st.integers(-1, 3)),
                max_size=150, unique_by=lambda edge: (min(edge[:2]), max(edge[:2]))))
def test_polylines_draw_every_edge_once_in_its_own_class(edges: list[tuple[int, int, int]]
                                                         ) -> None:
    pairs = np.array([edge[:2] for edge in edges], dtype=np.int64).reshape(-1, 2)
    classes = np.array([edge[2] for edge in edges], dtype=np.int64)
    nodes, starts, strip_classes = edge_strips(pairs, classes)
    wanted = sorted((min(a, b), max(a, b), c) for (a, b), c in zip(pairs.tolist(),
                                                                   classes.tolist(), strict=True)
                    if a != b)  # a node joined to itself draws nothing
    polylines = [nodes[begin:end] for begin, end in pairwise(starts)]
    assert _segments(polylines, list(strip_classes)) == wanted
    assert starts[0] == 0 and starts[-1] == len(nodes)


def test_a_mesh_needs_about_one_point_per_edge_and_closed_loops_close() -> None:
    side = 30  # a triangulated grid, as a GNG on a surface: degree ~6
    grid = np.arange(side * side).reshape(side, side)
    pairs = np.concatenate([
        np.stack([grid[:, :-1].ravel(), grid[:, 1:].ravel()], axis=1),
        np.stack([grid[:-1, :].ravel(), grid[1:, :].ravel()], axis=1),
        np.stack([grid[:-1, :-1].ravel(), grid[1:, 1:].ravel()], axis=1)])
    classes = (grid.ravel()[pairs[:, 0]] % side >= side // 2).astype(np.int64)  # two halves
    nodes, starts, strip_classes = edge_strips(pairs, classes)
    assert len(nodes) < 1.2 * len(pairs)  # against 2 points per edge unchained
    assert len(strip_classes) < 0.1 * len(pairs)

    triangle = np.array([[0, 1], [1, 2], [2, 0]])
    nodes, starts, _ = edge_strips(triangle, np.zeros(3, dtype=np.int64))
    assert len(starts) == 2 and len(nodes) == 4 and nodes[0] == nodes[-1]


@given(st.lists(st.integers(0, 2**62), max_size=200), st.integers(1, 2**62))
def test_the_ends_order_is_numpys_stable_argsort(values: list[int], scale: int) -> None:
    from gngdt.core.kernels.strips import stable_order

    keys = np.array(values, dtype=np.int64) % scale  # many repeats at small scales
    np.testing.assert_array_equal(stable_order(keys), np.argsort(keys, kind="stable"))


@given(st.lists(st.integers(-1, 2**40), min_size=1, max_size=300))
def test_an_id_has_one_colour_however_many_ids_are_coloured_with_it(ids: list[int]) -> None:
    colors = id_colors(np.array(ids * 3))  # over `DISTINCT_FIRST` ids from 22 on
    alone = np.array([id_colors(np.array([value]))[0] for value in ids * 3])
    np.testing.assert_array_equal(colors, alone)
    assert all(tuple(color) == (150, 150, 150) for color, value in zip(colors, ids * 3,
                                                                       strict=True) if value < 0)


def test_empty_and_self_loop_edges_draw_nothing() -> None:
    for pairs in (np.zeros((0, 2), dtype=np.int64), np.array([[3, 3]])):
        nodes, starts, classes = edge_strips(pairs, np.zeros(len(pairs), dtype=np.int64))
        assert len(nodes) == 0 and list(starts) == [0] and len(classes) == 0


def test_the_rrd_holds_nodes_once_with_each_clusterings_colours_and_views_pick_them(
        tmp_path) -> None:
    import rerun as rr
    from rerun.chunk import RrdReader

    from gngdt.io.outputs.rerun_blueprint import CLUSTERING_VIEWS, EntityPaths, blueprint
    from gngdt.io.outputs.rerun_log import RerunLog
    from gngdt.schemas.cluster_colors import UNCLUSTERED_RGB, clustering_edges
    from gngdt.schemas.topology import TopologySnapshot
    from gngdt.schemas.wire import FrameStamp

    rng = np.random.default_rng(1)
    positions = rng.random((60, 3)).astype(np.float32)
    ring = np.stack([np.arange(60), (np.arange(60) + 1) % 60], axis=1)
    chords = rng.integers(0, 60, (40, 2))
    edges = {"pos": np.concatenate([ring, chords]), "col": ring, "nor": ring[:30]}
    labels = {"pos": np.zeros(60, np.int32), "col": (np.arange(60) // 20).astype(np.int32),
              "nor": np.where(np.arange(60) < 31, 0, -1).astype(np.int32)}
    labels["col+nor"] = labels["nor"]  # "segments" is not published: grey, no edges
    snapshot = TopologySnapshot(
        positions, rng.integers(0, 255, (60, 3)).astype(np.uint8), None, None, edges, labels,
        steps=1, frame_sequence=0, timestamp_ns=1, frame_id="camera",
        cluster_counts={name: 1 for name in labels}, cluster_ids={"col": np.array([7, 8, 9])})
    path = tmp_path / "drawn.rrd"
    recording = rr.RecordingStream("gngdt-test")
    recording.save(str(path), default_blueprint=blueprint(["camera"]))
    rerun_log = RerunLog(recording)
    rerun_log.set_time(FrameStamp(0, 1_700_000_000_000_000_000))
    rerun_log.topology(EntityPaths("camera"), snapshot, draw=True)
    recording.flush()
    recording.disconnect()

    columns: dict[str, dict[str, list]] = {}
    reader = RrdReader(str(path))
    for chunk in reader.stream().to_chunks():
        batch = chunk.to_record_batch()
        columns.setdefault(str(chunk.entity_path), {}).update(
            {name: batch.column(name).to_pylist()[-1] for name in batch.schema.names
             if ":" in name})
    nodes = columns["/world/gng/nodes"]
    assert len(nodes["Points3D:positions"]) == 60

    def rgb(packed: list[int]) -> list[tuple[int, int, int]]:  # rerun packs colours as RGBA
        return [(value >> 24, value >> 16 & 255, value >> 8 & 255) for value in packed]

    for name in CLUSTERING_VIEWS:
        logged_colors = rgb(nodes[f"gngdt.clusters.{name}:colors"])
        strips = columns[f"/world/gng/edges/{name}".replace("+", "\\+")]
        if name not in labels:
            assert logged_colors == [UNCLUSTERED_RGB] and strips["LineStrips3D:strips"] == []
            continue
        ids = node_cluster_ids(labels[name], snapshot.cluster_ids.get(name), 5)
        assert logged_colors == [tuple(c) for c in id_colors(ids).tolist()]
        # every edge of the clustering drawn once, in the colour of the cluster of its ends
        index = {tuple(p): i for i, p in enumerate(positions.tolist())}  # float32 both
        polylines = [[index[tuple(p)] for p in strip] for strip in strips["LineStrips3D:strips"]]
        pairs = clustering_edges(name, edges, labels[name])
        colors = id_colors(edge_classes(pairs, ids))
        assert _segments(polylines, rgb(strips["LineStrips3D:colors"])) == sorted(
            (min(a, b), max(a, b), tuple(c))
            for (a, b), c in zip(pairs.tolist(), colors.tolist(), strict=True))

    # each clustering's view draws the nodes with that clustering's colours
    mapped = set()
    for chunk in reader.stream(store=reader.blueprints()[-1]).to_chunks():
        batch = chunk.to_record_batch()
        if "VisualizerInstruction:component_map" in batch.schema.names:
            assert "/overrides/world/gng/nodes/" in str(chunk.entity_path)
            for mapping in batch.column("VisualizerInstruction:component_map").to_pylist()[-1]:
                assert mapping["target"] == "Points3D:colors"
                mapped.add(mapping["source_component"])
    assert mapped == {f"gngdt.clusters.{name}:colors" for name in CLUSTERING_VIEWS}
    assert mapped <= set(nodes)
