"""The fast kernel against the readable reference, and the online learning contract."""

from __future__ import annotations

import numpy as np
import pytest

from gngdt_core import GNG, GNGDT, GNGW, make_data1, make_data2
from gngdt_core.reference import ReferenceGNGDT

SMALL = {"max_nodes": 60, "lambda_": 100, "age_max": 30, "random_state": 3}


def _edge_set(edges) -> set[tuple[int, int]]:
    return {(int(i), int(j)) for i, j in edges}


@pytest.mark.parametrize("make_data", [make_data1, make_data2], ids=["2d-colour", "3d-colour"])
def test_kernel_matches_reference(make_data):
    # 60 nodes > the grid threshold, so both winner searches (brute force, grid) are exercised
    positions, colors, _ = make_data(1.0, n_points=5_000, random_state=0)
    fast = GNGDT(**SMALL).fit(positions, colors, n_steps=15_000)
    reference = ReferenceGNGDT(**SMALL).partial_fit(positions, colors, n_steps=15_000)
    assert fast.n_nodes_ == len(reference.errors) == SMALL["max_nodes"]
    np.testing.assert_allclose(fast.positions_, reference.positions, rtol=0, atol=1e-9)
    np.testing.assert_allclose(fast.colors_, reference.colors, rtol=0, atol=1e-9)
    np.testing.assert_allclose(fast.normals_, reference.normals, rtol=0, atol=1e-9)
    np.testing.assert_allclose(fast.errors_, reference.errors, rtol=1e-9)
    np.testing.assert_array_equal(fast.node_ids_, reference.ids)
    for prop in fast.properties_:
        expected = {key for key, edge in reference.edges.items() if prop in edge.properties}
        assert _edge_set(fast.edges(prop)) == expected, prop


def test_node_ids_survive_deletions_as_in_the_reference():
    # age_max=3 makes nodes lose all their edges and be deleted (the last node moves into the
    # hole), so identities differ from indices; ids must follow each node like the reference's
    positions, colors, _ = make_data1(1.0, n_points=2_000, random_state=0)
    params = {**SMALL, "age_max": 3}
    fast = GNGDT(**params).fit(positions, colors, n_steps=6_000)
    reference = ReferenceGNGDT(**params).partial_fit(positions, colors, n_steps=6_000)
    np.testing.assert_allclose(fast.positions_, reference.positions, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(fast.node_ids_, reference.ids)
    assert reference.next_id > fast.n_nodes_ + 20  # many nodes were deleted
    assert np.unique(fast.node_ids_).size == fast.n_nodes_
    assert not np.array_equal(fast.node_ids_, np.arange(fast.n_nodes_))


def test_node_ids_persist_between_batches_and_are_never_reused():
    positions, colors, _ = make_data2(n_points=5_000, random_state=0)
    model = GNGDT(max_nodes=80, lambda_=100, age_max=5, random_state=0)
    model.partial_fit(positions, colors, n_steps=10_000)
    seen = set(model.node_ids_.tolist())
    before = dict(zip(model.node_ids_.tolist(), model.positions_, strict=True))
    model.partial_fit(positions, colors, n_steps=200)
    after = dict(zip(model.node_ids_.tolist(), model.positions_, strict=True))
    kept = before.keys() & after.keys()
    assert len(kept) >= 0.9 * len(before)
    # 200 steps move a node far less than the node spacing: a kept id is the same node
    moves = [np.linalg.norm(after[i] - before[i]) for i in kept]
    assert max(moves) < 0.5 * np.median(np.linalg.norm(np.diff(model.positions_, axis=0), axis=1))
    new = after.keys() - before.keys()
    assert all(i >= max(seen) + 1 for i in new)
    assert model.node_ids_.dtype == np.int64


def test_same_seed_same_result_and_different_seed_differs():
    positions, colors, _ = make_data2(n_points=5_000, random_state=0)
    runs = [GNGDT(max_nodes=100, random_state=seed).fit(positions, colors, n_steps=30_000)
            for seed in (7, 7, 8)]
    np.testing.assert_array_equal(runs[0].positions_, runs[1].positions_)
    np.testing.assert_array_equal(runs[0].edges("nor"), runs[1].edges("nor"))
    assert runs[0].positions_.shape != runs[2].positions_.shape or not np.array_equal(
        runs[0].positions_, runs[2].positions_)


def test_growth_stops_at_max_nodes_and_adaptation_continues():
    positions, colors, _ = make_data1(n_points=2_000, random_state=0)
    model = GNGDT(max_nodes=20, lambda_=50, random_state=0).fit(positions, colors, n_steps=5_000)
    assert model.n_nodes_ == 20
    before = model.positions_
    model.partial_fit(positions, colors, n_steps=5_000)
    assert model.n_nodes_ == 20
    assert model.n_steps_ == 10_000
    assert not np.array_equal(before, model.positions_)


def test_n_steps_beyond_the_batch_and_default_one_pass():
    positions, colors, _ = make_data1(n_points=300, random_state=0)
    model = GNGDT(max_nodes=50, lambda_=100, random_state=0)
    model.partial_fit(positions, colors)
    assert model.n_steps_ == 300
    model.partial_fit(positions, colors, n_steps=2_500)
    assert model.n_steps_ == 2_800
    assert model.n_nodes_ == 2 + 2_800 // 100


def test_invalid_rows_are_dropped_and_counted():
    positions, colors, _ = make_data2(n_points=1_000, random_state=0)
    dirty_positions = positions.copy()
    dirty_colors = colors.copy()
    dirty_positions[::10, 1] = np.nan
    dirty_positions[5, 2] = np.inf
    dirty_colors[7, 0] = -np.inf
    model = GNGDT(max_nodes=30, lambda_=100, random_state=0)
    model.partial_fit(dirty_positions, dirty_colors, n_steps=3_000)
    assert model.n_invalid_ == 102
    assert np.isfinite(model.positions_).all() and np.isfinite(model.colors_).all()
    model.partial_fit(dirty_positions, dirty_colors, n_steps=10)
    assert model.n_invalid_ == 204
    # a batch of nothing but invalid rows is a no-op
    model.partial_fit(np.full((4, 3), np.nan), np.zeros((4, 3)))
    assert model.n_invalid_ == 208 and model.n_steps_ == 3_010


def test_without_colours_and_in_2d_the_property_sets_follow():
    positions3, _, _ = make_data2(n_points=2_000, random_state=0)
    model = GNGDT(max_nodes=30, lambda_=100, random_state=0).fit(positions3, n_steps=3_000)
    assert model.properties_ == ("pos", "nor")
    positions2, colors2, _ = make_data1(n_points=2_000, random_state=0)
    model2 = GNGDT(max_nodes=30, lambda_=100, random_state=0)
    model2.fit(positions2, colors2, n_steps=3_000)
    assert model2.properties_ == ("pos", "col")
    assert not model2.normals_.any()
    with pytest.raises(ValueError, match="nor"):
        model2.edges("nor")


def test_a_large_colourless_batch_learns_positions_only():
    positions, _, _ = make_data2(random_state=0)  # 112,500 points, no colours given
    model = GNGDT(max_nodes=50, random_state=0).fit(positions, n_steps=len(positions))
    assert model.n_nodes_ == 50 and not model.colors_.any()


def test_normals_are_unit_and_face_the_viewpoint():
    positions, colors, _ = make_data2(n_points=20_000, random_state=0)
    viewpoint = np.array([150.0, -200.0, 300.0])
    model = GNGDT(max_nodes=200, viewpoint=tuple(viewpoint), random_state=0)
    model.fit(positions, colors, n_steps=150_000)
    normals = model.normals_
    defined = np.linalg.norm(normals, axis=1) > 0
    assert defined.mean() > 0.9
    np.testing.assert_allclose(np.linalg.norm(normals[defined], axis=1), 1.0, atol=1e-9)
    towards = np.sum(normals * (viewpoint - model.positions_), axis=1)
    assert np.all(towards[defined] >= 0)


@pytest.mark.parametrize("cls", [GNG, GNGW])
def test_baselines_keep_one_topology_and_learn_colour(cls):
    positions, colors, _ = make_data1(n_points=3_000, random_state=0)
    model = cls(max_nodes=40, lambda_=100, random_state=0).fit(positions, colors, n_steps=8_000)
    assert model.properties_ == ("pos",)
    assert model.n_nodes_ == 40
    errors = model.quantization_error(positions, colors)
    assert set(errors) == {"pos", "col"}
    # colours were learned: far better than the mean colour of the data as a single prototype
    assert errors["col"] < np.sqrt(np.mean(np.sum((colors - colors.mean(0)) ** 2, axis=1)))
    labels = model.clusters("pos")
    assert labels.shape == (40,) and labels.min() == 0


def test_gngw_weights_change_the_result():
    positions, colors, _ = make_data1(0.01, n_points=3_000, random_state=0)
    a = GNGW(max_nodes=40, lambda_=100, random_state=0).fit(positions, colors, n_steps=8_000)
    b = GNGW(max_nodes=40, lambda_=100, w_pos=0.99, w_col=0.01, random_state=0).fit(
        positions, colors, n_steps=8_000)
    assert not np.array_equal(a.positions_, b.positions_)
