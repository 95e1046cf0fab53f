"""Bad parameters and bad arrays raise ValueError naming the culprit (parameters when learning
starts, as scikit-learn's estimators check them)."""

from __future__ import annotations

import numpy as np
import pytest

from gngdt.core import GNG, GNGDT, GNGW


@pytest.mark.parametrize(
    ("cls", "params", "name"),
    [
        (GNGDT, {"max_nodes": 1}, "max_nodes"),
        (GNGDT, {"max_nodes": 10.5}, "max_nodes"),
        (GNGDT, {"max_nodes": 10**12}, "max_nodes"),
        (GNGDT, {"lambda_": 0}, "lambda_"),
        (GNGDT, {"eta1": -0.1}, "eta1"),
        (GNGDT, {"eta2": -1e-4}, "eta2"),
        (GNGDT, {"eta1": 0.01, "eta2": 0.1}, "eta2"),
        (GNGDT, {"age_max": 0}, "age_max"),
        (GNGDT, {"alpha": 1.5}, "alpha"),
        (GNGDT, {"beta": -0.1}, "beta"),
        (GNGDT, {"beta": 1.0}, "beta"),
        (GNGDT, {"tau_col": 0.0}, "tau_col"),
        (GNGDT, {"tau_nor": -1.0}, "tau_nor"),
        (GNGDT, {"tau_col": float("nan")}, "tau_col"),
        (GNGDT, {"normal_mu": 0.0}, "normal_mu"),
        (GNGDT, {"viewpoint": (0.0, 1.0)}, "viewpoint"),
        (GNGDT, {"random_state": -3}, "random_state"),
        (GNGW, {"w_pos": -0.5}, "w_pos"),
        (GNGW, {"w_col": float("inf")}, "w_col"),
        (GNG, {"eta1": "fast"}, "eta1"),
    ],
)
def test_bad_parameters(cls, params, name):
    model = cls(**params)  # stored as given; checked by fit and partial_fit
    points = np.random.default_rng(1).random((50, 3))
    for learn in (model.fit, model.partial_fit):
        with pytest.raises(ValueError, match=name):
            learn(points, points, n_steps=10)
    with pytest.raises(ValueError, match=name):
        model.check_params()
    assert model.n_nodes_ == 0


RNG = np.random.default_rng(0)


@pytest.mark.parametrize(
    ("positions", "colors", "name"),
    [
        (RNG.random(10), None, "positions"),
        (RNG.random((10, 4)), None, "positions"),
        (RNG.random((10, 1)), None, "positions"),
        (np.array([["a", "b", "c"]]), None, "positions"),
        (RNG.random((10, 3)), RNG.random((9, 3)), "colors"),
        (RNG.random((10, 3)), RNG.random((10, 4)), "colors"),
        (RNG.random((10, 3)), RNG.random(10), "colors"),
    ],
)
def test_bad_arrays(positions, colors, name):
    with pytest.raises(ValueError, match=name):
        GNGDT(max_nodes=10).partial_fit(positions, colors)


def test_later_batches_must_match_the_first():
    model = GNGDT(max_nodes=10, random_state=0)
    model.partial_fit(RNG.random((50, 3)), RNG.random((50, 3)))
    with pytest.raises(ValueError, match="positions"):
        model.partial_fit(RNG.random((50, 2)), RNG.random((50, 3)))
    with pytest.raises(ValueError, match="colors"):
        model.partial_fit(RNG.random((50, 3)))
    with pytest.raises(ValueError, match="n_steps"):
        model.partial_fit(RNG.random((50, 3)), RNG.random((50, 3)), n_steps=-1)


def test_queries_are_checked():
    model = GNGDT(max_nodes=10, random_state=0)
    with pytest.raises(ValueError, match="no nodes"):
        model.predict(RNG.random((5, 3)))
    model.partial_fit(RNG.random((50, 3)))
    with pytest.raises(ValueError, match="positions"):
        model.predict(RNG.random((5, 2)))
    with pytest.raises(ValueError, match="NaN"):
        model.predict(np.full((1, 3), np.nan))
    with pytest.raises(ValueError, match="unknown property"):
        model.clusters("col")
    with pytest.raises(ValueError, match="min_size"):
        model.clusters("pos", min_size=0)


def test_finite_rows_screen_is_exact_including_overflowing_sums():
    from gngdt.core.gas.sampling import finite_rows

    rows = np.ones((6, 3), dtype=np.float32)
    assert finite_rows(rows) is None
    rows[1, 2] = np.nan
    rows[3, 0] = np.inf
    rows[4] = [np.inf, -np.inf, 1.0]  # sums to NaN
    assert finite_rows(rows).tolist() == [True, False, True, False, False, True]
    huge = np.full((2, 3), 3e38, dtype=np.float32)  # finite, but the row sums overflow
    assert finite_rows(huge) is None
    assert finite_rows(np.full((2, 3), 1.7e308)) is None  # float64 sums overflow too
    assert finite_rows(np.zeros((4, 3), dtype=np.uint8)) is None
    half = np.ones((3, 3), dtype=np.float16)  # no numba kernel for float16: numpy's test
    half[2, 1] = np.nan
    assert finite_rows(half).tolist() == [True, True, False]


def test_finite_rows_of_a_decoded_cloud_reads_its_strided_points():
    """A decoded cloud's points are a read-only view with a 15-byte stride; a NaN in any field
    of any row is found, wherever it is."""
    from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud

    from gngdt.core.gas.sampling import finite_rows
    from gngdt.schemas.clouds import cloud_to_wire, msg_to_cloud

    positions = np.random.default_rng(0).random((1000, 3), dtype=np.float32)
    colors = np.zeros((1000, 3), dtype=np.uint8)
    for row, column in [(None, None), (0, 0), (517, 1), (999, 2)]:
        damaged = positions.copy()
        if row is not None:
            damaged[row, column] = np.nan if column != 1 else -np.inf
        wire = cloud_to_wire(damaged, colors, timestamp_ns=1, frame_id="camera", pose=None)
        points, _ = msg_to_cloud(PointCloud.FromString(bytes(wire)), copy=False)
        assert points.strides[0] == 15 and not points.flags.writeable
        finite = finite_rows(points)
        if row is None:
            assert finite is None
        else:
            assert np.flatnonzero(~finite).tolist() == [row]
