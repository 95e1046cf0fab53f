"""The fast kernel against the readable reference, and the online learning contract."""

from __future__ import annotations

import numpy as np
import pytest

from gngdt.core import GNG, GNGDT, GNGW
from gngdt.core.kernels import layout as K
from gngdt.eval.reference import ReferenceGNGDT
from gngdt.eval.synthetic import make_data1, make_data2

# Table 1's rates and ages with a small budget: 60 nodes, more than the grid search's threshold
SMALL = {"max_nodes": 60, "lambda_": 100, "age_max": 30, "random_state": 3}
# Edges that expire after 2 ages delete ~200 nodes in 6,000 steps, and beta = 0.05 takes the lazy
# error scale below its floor (1e-60) every ~2,700 steps; 60 nodes keep the grid search on.
CHURN = {"max_nodes": 60, "lambda_": 20, "age_max": 2, "beta": 0.05, "random_state": 3}
CHURN_STEPS = 6_000
# Edges that expire after one age, a node every 10 steps: ~300 deletions in 3,000 steps, several
# in one step now and then; their order (the kernel's slot order) decides the nodes' indices.
MASS_DELETION = {**CHURN, "lambda_": 10, "age_max": 1}
MASS_DELETION_STEPS = 3_000
# Edges that never expire and nodes that jump halfway to every input (eta1 = eta2 = 0.5) connect
# nearly every pair of 24 nodes: winners hit the 16-edge cap within a few hundred steps.
CAP = {"max_nodes": 24, "lambda_": 20, "age_max": 100_000, "eta1": 0.5, "eta2": 0.5,
       "random_state": 3}
CAP_STEPS = 3_000
# The kernel's closed-form eigenvector differs from eigh by up to ~1e-3 where the two smallest
# eigenvalues of eq. 16's covariance nearly coincide (acos loses half the digits there); normals
# move no position or colour and age no edge, so this tolerance cannot hide a wrong network.
NORMAL_ATOL = 2e-3
_BITS = (("col", K.COL_BIT), ("nor", K.NOR_BIT))


def _kernel_edges(model: GNGDT) -> dict[tuple[int, int], tuple[int, frozenset[str]]]:
    """Every edge ``i < j`` of the fast model: (age, properties)."""
    a, edges = model._arrays, {}
    for i in range(model.n_nodes_):
        for k in range(a["deg"][i]):
            j = int(a["nbr"][i, k])
            if i < j:
                bits = int(a["emask"][i, k])
                props = {"pos"} | {p for p, bit in _BITS if bits & bit and p in model.properties_}
                edges[(i, j)] = (int(a["age"][i, k]), frozenset(props))
    return edges


def _reference_edges(reference: ReferenceGNGDT, properties: tuple[str, ...]):
    return {key: (edge.age, frozenset(edge.properties & set(properties)))
            for key, edge in reference.edges.items()}


def _assert_same_network(fast: GNGDT, reference: ReferenceGNGDT, step: int) -> None:
    where = f"after step {step}"
    assert fast.n_nodes_ == len(reference.errors), where
    np.testing.assert_allclose(fast.positions_, reference.positions, rtol=0, atol=1e-9,
                               err_msg=where)
    np.testing.assert_allclose(fast.colors_, reference.colors, rtol=0, atol=1e-9, err_msg=where)
    np.testing.assert_allclose(fast.errors_, reference.errors, rtol=1e-9,
                               atol=1e-12 * max(reference.errors.max(), 1e-300), err_msg=where)
    np.testing.assert_allclose(fast.normals_, reference.normals, rtol=0, atol=NORMAL_ATOL,
                               err_msg=where)
    np.testing.assert_array_equal(fast.node_ids_, reference.ids, err_msg=where)
    assert _kernel_edges(fast) == _reference_edges(reference, fast.properties_), where


def _learn_side_by_side(params: dict, positions, colors, steps: int) -> dict[str, int]:
    """Both learners one step at a time on the same samples, compared after every step.

    Returns what happened: nodes deleted, steps deleting two or more nodes, degree-cap events
    (the reference counts both), renormalisations of the kernel's lazy error scale, and whether
    the kernel's winner search ended on the grid.
    """
    fast, reference = GNGDT(**params), ReferenceGNGDT(**params)
    seen = {"several_deleted": 0, "renormalised": 0}
    for step in range(1, steps + 1):
        scale = fast._fstate[K.F_ERROR_SCALE]
        deleted = reference.events["deleted_nodes"]
        fast.partial_fit(positions, colors, n_steps=1)
        reference.partial_fit(positions, colors, n_steps=1)
        _assert_same_network(fast, reference, step)
        seen["renormalised"] += int(fast._fstate[K.F_ERROR_SCALE] > scale)
        seen["several_deleted"] += int(reference.events["deleted_nodes"] - deleted >= 2)
    seen["deleted_nodes"] = reference.events["deleted_nodes"]
    seen["degree_cap"] = reference.events["degree_cap"]
    seen["grid_search"] = int(fast._istate[K.I_GRID])
    return seen


@pytest.mark.parametrize("make_data", [make_data1, make_data2], ids=["2d-colour", "3d-colour"])
def test_kernel_matches_reference_step_by_step_through_deletions(make_data):
    positions, colors, _ = make_data(1.0, n_points=5_000, random_state=0)
    seen = _learn_side_by_side(CHURN, positions, colors, CHURN_STEPS)
    assert seen["deleted_nodes"] >= 50, seen
    assert seen["renormalised"] >= 2, seen
    assert seen["grid_search"], seen


@pytest.mark.parametrize("make_data", [make_data1, make_data2], ids=["2d-colour", "3d-colour"])
def test_kernel_matches_reference_step_by_step_deleting_several_nodes_at_once(make_data):
    positions, colors, _ = make_data(1.0, n_points=5_000, random_state=0)
    seen = _learn_side_by_side(MASS_DELETION, positions, colors, MASS_DELETION_STEPS)
    assert seen["several_deleted"] >= 3, seen
    assert seen["renormalised"] >= 1, seen


def test_kernel_matches_reference_step_by_step_at_the_degree_cap():
    # 2-D: the same churn in 3-D leaves degenerate neighbourhoods, where eq. 16 has no unique
    # normal and the two eigen-solvers may disagree on whether one exists
    positions, colors, _ = make_data1(1.0, n_points=5_000, random_state=0)
    seen = _learn_side_by_side(CAP, positions, colors, CAP_STEPS)
    assert seen["degree_cap"] >= 10, seen


@pytest.mark.parametrize("make_data", [make_data1, make_data2], ids=["2d-colour", "3d-colour"])
def test_kernel_matches_reference_with_table1_rates(make_data):
    # compared every 1,000 steps while 60 nodes grow (to step 5,800) and then adapt
    positions, colors, _ = make_data(1.0, n_points=5_000, random_state=0)
    fast, reference = GNGDT(**SMALL), ReferenceGNGDT(**SMALL)
    for step in range(1_000, 15_001, 1_000):
        fast.partial_fit(positions, colors, n_steps=1_000)
        reference.partial_fit(positions, colors, n_steps=1_000)
        _assert_same_network(fast, reference, step)
    assert fast.n_nodes_ == SMALL["max_nodes"]


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


def test_gng_without_colour_learns_gngdts_positions_and_edges():
    # the same distance (position alone), so the same winners, moves and edges: GNG takes
    # GNG-DT's grid search then, and must find the very nodes its brute force would
    positions, _, _ = make_data2(n_points=5_000, random_state=0)
    gng = GNG(max_nodes=120, lambda_=100, random_state=0).fit(positions, n_steps=30_000)
    gngdt = GNGDT(max_nodes=120, lambda_=100, random_state=0).fit(positions, n_steps=30_000)
    assert gng.n_nodes_ == 120
    np.testing.assert_array_equal(gng.positions_, gngdt.positions_)
    np.testing.assert_array_equal(gng.edges("pos"), gngdt.edges("pos"))


def test_gngw_weights_change_the_result():
    positions, colors, _ = make_data1(0.01, n_points=3_000, random_state=0)
    a = GNGW(max_nodes=40, lambda_=100, random_state=0).fit(positions, colors, n_steps=8_000)
    b = GNGW(max_nodes=40, lambda_=100, w_pos=0.99, w_col=0.01, random_state=0).fit(
        positions, colors, n_steps=8_000)
    assert not np.array_equal(a.positions_, b.positions_)
