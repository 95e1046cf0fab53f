"""get_state / from_state: exact continuation, through np.savez, and refusal of bad states."""

from __future__ import annotations

import numpy as np
import pytest

from gngdt.core import GNG, GNGDT, GNGW
from gngdt.eval.synthetic import make_data1, make_data2


def _roundtrip(state: dict[str, np.ndarray], path) -> dict[str, np.ndarray]:
    np.savez(path, **state)
    with np.load(path, allow_pickle=False) as loaded:
        return {key: loaded[key] for key in loaded.files}


def _assert_same_state(a: dict[str, np.ndarray], b: dict[str, np.ndarray]) -> None:
    assert a.keys() == b.keys()
    for key in a:
        np.testing.assert_array_equal(a[key], b[key], err_msg=key)


@pytest.mark.parametrize("cls", [GNGDT, GNG, GNGW])
def test_checkpoint_restore_continue_equals_uninterrupted(cls, tmp_path):
    positions, colors, _ = make_data2(n_points=10_000, random_state=0)
    params = {"max_nodes": 150, "lambda_": 200, "random_state": 5}
    uninterrupted = cls(**params)
    uninterrupted.partial_fit(positions, colors, n_steps=25_000)
    uninterrupted.partial_fit(positions, colors, n_steps=25_000)

    first = cls(**params).partial_fit(positions, colors, n_steps=25_000)
    state = _roundtrip(first.get_state(), tmp_path / "checkpoint.npz")
    restored = cls.from_state(state)
    _assert_same_state(first.get_state(), restored.get_state())
    restored.partial_fit(positions, colors, n_steps=25_000)
    _assert_same_state(uninterrupted.get_state(), restored.get_state())


def test_node_ids_and_their_counter_survive_a_checkpoint(tmp_path):
    positions, colors, _ = make_data2(n_points=5_000, random_state=0)
    model = GNGDT(max_nodes=60, lambda_=100, age_max=5, random_state=0)
    model.partial_fit(positions, colors, n_steps=20_000)
    restored = GNGDT.from_state(_roundtrip(model.get_state(), tmp_path / "ids.npz"))
    np.testing.assert_array_equal(restored.node_ids_, model.node_ids_)
    for learner in (model, restored):
        learner.partial_fit(positions, colors, n_steps=20_000)
    np.testing.assert_array_equal(restored.node_ids_, model.node_ids_)


def test_a_state_saved_before_node_ids_gets_fresh_ids():
    positions, colors, _ = make_data1(n_points=2_000, random_state=0)
    growing = GNGDT(max_nodes=60, lambda_=50, random_state=0).fit(positions, colors, n_steps=1_000)
    old = {key: value for key, value in growing.get_state().items() if key != "ids"}
    old["counters"] = old["counters"][:3]  # the layout before node ids
    restored = GNGDT.from_state(old)
    n = restored.n_nodes_
    np.testing.assert_array_equal(restored.node_ids_, np.arange(n))
    np.testing.assert_array_equal(restored.positions_, growing.positions_)
    restored.partial_fit(positions, colors, n_steps=500)
    assert restored.n_nodes_ > n and restored.node_ids_.max() >= n
    assert np.unique(restored.node_ids_).size == restored.n_nodes_


def test_unfitted_state_roundtrips(tmp_path):
    model = GNGDT(max_nodes=10, random_state=1)
    restored = GNGDT.from_state(_roundtrip(model.get_state(), tmp_path / "s.npz"))
    assert restored.n_nodes_ == 0 and restored.max_nodes == 10


@pytest.fixture(scope="module")
def fitted_state() -> dict[str, np.ndarray]:
    positions, colors, _ = make_data1(n_points=2_000, random_state=0)
    return GNGDT(max_nodes=30, lambda_=50, random_state=0).fit(
        positions, colors, n_steps=3_000).get_state()


def _corrupt(state, key, change):
    bad = {k: v.copy() for k, v in state.items()}
    bad[key] = change(bad[key])
    return bad


def _swap_neighbour(nbr):
    nbr[0, 0] = (nbr[0, 0] + 1) % len(nbr)
    return nbr


@pytest.mark.parametrize(
    ("key", "change", "message"),
    [
        ("pos", lambda a: a[:-1], "pos"),
        ("pos", lambda a: np.where(a == a[0, 0], np.nan, a), "pos"),
        ("nbr", _swap_neighbour, "symmetric|nbr"),
        ("deg", lambda a: a + 40, "deg"),
        ("age", lambda a: a - 1000, "age"),
        ("emask", lambda a: a & 0, "emask"),
        ("model", lambda a: np.array("GNG"), "GNG"),
        ("params", lambda a: np.array("{not json"), "JSON"),
        ("params", lambda a: np.array("7"), "JSON object"),
        ("params", lambda a: np.array(str(a).replace('"max_nodes": ', '"max_nodes": 99999999')),
         r"max_nodes must be in \[2, 10000000\]"),
        ("counters", lambda a: np.array([10_000, 0, 0]), "nodes"),
        ("counters", lambda a: np.array([a[0], a[1], a[2], 1]), "next id"),
        ("ids", lambda a: np.zeros_like(a), "distinct"),
        ("ids", lambda a: a[:-1], "ids"),
        ("err", lambda a: a.astype(np.int64), "err"),
    ],
)
def test_inconsistent_states_are_refused(fitted_state, key, change, message):
    with pytest.raises(ValueError, match=message):
        GNGDT.from_state(_corrupt(fitted_state, key, change))


def test_missing_key_is_refused(fitted_state):
    state = dict(fitted_state)
    del state["rev"]
    with pytest.raises(ValueError, match="rev"):
        GNGDT.from_state(state)
