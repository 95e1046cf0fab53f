"""Clustering of combined topologies, eq. 17-18 metrics and the adjusted Rand index."""

from __future__ import annotations

import numpy as np
import pytest

from gngdt.core import (
    GNGDT,
    adjusted_rand_index,
    cluster_centre_errors,
    connected_component_labels,
)
from gngdt.eval.synthetic import make_data1


def test_components_sorted_by_size_with_min_size():
    # components: {0,1,2,3}, {4,5}, {6}
    edges = np.array([[0, 1], [1, 2], [2, 3], [4, 5]])
    labels = connected_component_labels(7, edges)
    np.testing.assert_array_equal(labels, [0, 0, 0, 0, 1, 1, 2])
    labels = connected_component_labels(7, edges, min_size=2)
    np.testing.assert_array_equal(labels, [0, 0, 0, 0, 1, 1, -1])


def test_components_are_scipys_on_random_graphs():
    """The union-find gives the partition scipy's csgraph gives (ranked the same way), with
    self-loops, repeated edges, either direction and isolated nodes."""
    from scipy.sparse import coo_array
    from scipy.sparse.csgraph import connected_components

    from gngdt.core.clustering import rank_by_size

    rng = np.random.default_rng(1)
    for _ in range(200):
        n = int(rng.integers(1, 300))
        edges = rng.integers(0, n, (int(rng.integers(0, 2 * n)), 2))
        graph = coo_array((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n))
        _, raw = connected_components(graph.tocsr(), directed=False)
        np.testing.assert_array_equal(connected_component_labels(n, edges, 2),
                                      rank_by_size(raw, 2))


def test_cluster_count_counts_distinct_labels_but_none():
    from gngdt.core.clustering import cluster_count

    rng = np.random.default_rng(3)
    for size, high in ((0, 1), (1, 1), (50, 3), (3_000, 40), (3_000, 2**40)):
        labels = rng.integers(-1, high, size)
        assert cluster_count(labels) == np.unique(labels[labels >= 0]).size
    assert cluster_count(np.array([-1, -1])) == 0


def test_components_refuse_edges_to_nodes_that_do_not_exist():
    with pytest.raises(ValueError, match=r"nodes 0\.\.2"):
        connected_component_labels(3, np.array([[0, 3]]))


def test_combined_topology_keeps_only_edges_in_every_property():
    positions, colors, _ = make_data1(n_points=3_000, random_state=0)
    model = GNGDT(max_nodes=60, lambda_=100, random_state=0).fit(positions, colors, n_steps=20_000)
    pos_edges = {tuple(e) for e in model.edges("pos")}
    col_edges = {tuple(e) for e in model.edges("col")}
    assert col_edges <= pos_edges and col_edges != pos_edges
    both = model.edges("pos", "col")  # col edges are a subset of pos edges: the col topology
    assert {tuple(e) for e in both} == col_edges
    assert model.edges().tolist() == model.edges("pos").tolist()
    expected = connected_component_labels(model.n_nodes_, np.array(sorted(col_edges)))
    np.testing.assert_array_equal(model.clusters("col"), expected)
    np.testing.assert_array_equal(model.clusters("pos", "col"), expected)


def test_node_spacing_by_the_learners_search_is_the_k_d_trees():
    from gngdt.core.sensor.view import node_spacing

    rng = np.random.default_rng(2)  # a box's floor and two walls, 3-D: the grid is searched
    positions = rng.random((6_000, 3))
    positions[np.arange(6_000) % 3, np.arange(6_000) % 3] = 0.0
    colors = rng.random((6_000, 3))
    model = GNGDT(max_nodes=300, lambda_=50, random_state=0)
    for _ in range(4):  # growing: the grid is rebuilt and nodes move between cells
        model.partial_fit(positions, colors, n_steps=3_000)
        assert model.node_spacing() == node_spacing(model.positions_) > 0
    assert GNGDT(random_state=0).node_spacing() == 0.0


def test_quantization_error_matches_a_brute_force_computation():
    positions, colors, _ = make_data1(n_points=2_000, random_state=1)
    model = GNGDT(max_nodes=40, lambda_=50, random_state=0).fit(positions, colors, n_steps=5_000)
    nodes = model.positions_
    distances = np.linalg.norm(positions[:, None, :] - nodes[None, :, :], axis=2)
    winners = distances.argmin(axis=1)
    expected_pos = np.sqrt(np.mean(distances.min(axis=1) ** 2))
    expected_col = np.sqrt(np.mean(np.sum((colors - model.colors_[winners]) ** 2, axis=1)))
    errors = model.quantization_error(positions, colors)
    assert errors["pos"] == pytest.approx(expected_pos, rel=1e-12)
    assert errors["col"] == pytest.approx(expected_col, rel=1e-12)
    np.testing.assert_array_equal(model.predict(positions), winners)


def test_cluster_centre_errors_match_clusters_to_centres():
    nodes = np.array([[0.0, 0.0], [2.0, 0.0], [10.0, 10.0], [12.0, 10.0], [50.0, 50.0]])
    labels = np.array([1, 1, 0, 0, -1])
    centres = np.array([[11.0, 11.0], [1.0, 0.0], [100.0, 100.0]])
    errors = cluster_centre_errors(nodes, labels, centres)
    np.testing.assert_allclose(errors[:2], [1.0, 0.0])
    assert errors[2] == np.inf


def test_adjusted_rand_index_known_values():
    assert adjusted_rand_index([0, 0, 1, 1], [5, 5, 7, 7]) == pytest.approx(1.0)
    # by hand from the contingency tables (pair counts: index, row sums, column sums of 6 pairs)
    # [[2,0],[1,1]]: index 1, rows 2, cols 3 -> expected 1, max 2.5 -> ARI 0
    assert adjusted_rand_index([0, 0, 1, 1], [0, 0, 0, 1]) == pytest.approx(0.0)
    # [[1,1],[1,1]]: index 0, rows 2, cols 2 -> expected 2/3, max 2 -> ARI -0.5
    assert adjusted_rand_index([0, 0, 1, 1], [0, 1, 0, 1]) == pytest.approx(-0.5)
    with pytest.raises(ValueError, match="length"):
        adjusted_rand_index([0, 1], [0, 1, 2])


def test_adjusted_rand_index_agrees_with_scikit_learn():
    metrics = pytest.importorskip(
        "sklearn.metrics", reason="scikit-learn (eval extra) not installed"
    )
    rng = np.random.default_rng(0)
    for _ in range(20):
        true = rng.integers(0, 4, size=200)
        pred = np.where(rng.random(200) < 0.7, true, rng.integers(-1, 6, size=200))
        assert adjusted_rand_index(true, pred) == pytest.approx(
            metrics.adjusted_rand_score(true, pred), abs=1e-12)


def test_point_labels_of_data1_recover_the_rectangles():
    positions, colors, labels = make_data1(n_points=10_000, random_state=0)
    model = GNGDT(max_nodes=300, random_state=1).fit(positions, colors, n_steps=200_000)
    point_labels = model.clusters("col", min_size=10)[model.predict(positions)]
    assert adjusted_rand_index(labels, point_labels) > 0.8
