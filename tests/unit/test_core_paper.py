"""The paper's simulation experiments (Section 3.1) on Data1 and Data2."""

from __future__ import annotations

import numpy as np
import pytest

from gngdt.core import GNG, GNGDT, GNGW, cluster_centre_errors
from gngdt.eval.synthetic import (
    DATA1_CENTRES,
    DATA2_CYLINDER,
    DATA2_FLOOR,
    DATA2_PRISM_BROWN_FACE,
    DATA2_PRISM_RED_FACE,
    make_data1,
    make_data2,
)

SCALES = (10.0, 1.0, 0.1, 0.01)
DATA1_NODES = 300
DATA1_STEPS = 200_000
# The colour topology leaves a few isolated nodes of mixed colour on the rectangles' borders (the
# paper's Figure 8); clusters of fewer than 10 nodes (of 300, i.e. ~1/7 of a rectangle's ~75)
# are not counted.
MIN_CLUSTER_SIZE = 10


@pytest.fixture(scope="module")
def data1_runs() -> dict[float, dict[str, object]]:
    runs: dict[float, dict[str, object]] = {}
    for scl in SCALES:
        positions, colors, labels = make_data1(scl, random_state=0)
        runs[scl] = {
            "data": (positions, colors, labels),
            **{cls.__name__: cls(max_nodes=DATA1_NODES, random_state=1).fit(
                positions, colors, n_steps=DATA1_STEPS) for cls in (GNGDT, GNG, GNGW)},
        }
    return runs


@pytest.mark.parametrize("scl", SCALES)
def test_data1_colour_topology_finds_the_four_rectangles(data1_runs, scl):
    model = data1_runs[scl]["GNGDT"]
    labels = model.clusters("col", min_size=MIN_CLUSTER_SIZE)
    assert labels.max() + 1 == 4
    # each cluster lies inside one rectangle: its nodes are within the rectangle's 150x150 square
    positions = model.positions_ / scl
    for cluster in range(4):
        members = positions[labels == cluster]
        quadrant = (members[:, 0] >= 150).astype(int) + 2 * (members[:, 1] >= 150)
        assert np.bincount(quadrant, minlength=4).max() >= 0.95 * len(members)
    errors = cluster_centre_errors(model.positions_, labels, DATA1_CENTRES * scl) / scl
    assert np.all(errors < 20.0), errors  # paper's Table 4: about 5.7 +- 1.7 at every scale


def test_data1_position_error_is_scale_invariant(data1_runs):
    scaled = []
    for scl in SCALES:
        positions, colors, _ = data1_runs[scl]["data"]
        scaled.append(data1_runs[scl]["GNGDT"].quantization_error(positions, colors)["pos"] / scl)
    scaled = np.array(scaled)
    assert np.all(np.abs(scaled / scaled.mean() - 1.0) <= 0.10), scaled


@pytest.mark.parametrize("scl", [0.1, 0.01])
def test_data1_gngdt_beats_the_baselines_at_small_scales(data1_runs, scl):
    positions, colors, _ = data1_runs[scl]["data"]
    errors = {name: data1_runs[scl][name].quantization_error(positions, colors)["pos"]
              for name in ("GNGDT", "GNG", "GNGW")}
    assert errors["GNGDT"] < errors["GNG"], errors
    assert errors["GNGDT"] < errors["GNGW"], errors


def test_data2_normal_topology_separates_floor_from_objects():
    positions, colors, labels = make_data2(random_state=0)
    model = GNGDT(max_nodes=800, random_state=2).fit(positions, colors, n_steps=500_000)
    winners = model.predict(positions)
    # ground truth of a node: the surface most of its points lie on
    counts = np.zeros((model.n_nodes_, 4), dtype=np.int64)
    np.add.at(counts, (winners, labels), 1)
    node_truth = counts.argmax(axis=1)
    assert (node_truth == DATA2_FLOOR).sum() > 0.5 * model.n_nodes_

    normal_clusters = model.clusters("nor", min_size=MIN_CLUSTER_SIZE)
    floor_cluster = np.bincount(normal_clusters[node_truth == DATA2_FLOOR] + 1).argmax() - 1
    assert floor_cluster >= 0
    in_floor_cluster = normal_clusters == floor_cluster
    # the floor's normal cluster holds (almost) the whole floor and nothing else
    assert in_floor_cluster[node_truth == DATA2_FLOOR].mean() > 0.8
    for surface in (DATA2_PRISM_RED_FACE, DATA2_PRISM_BROWN_FACE, DATA2_CYLINDER):
        assert not in_floor_cluster[node_truth == surface].any(), surface
    # while the position topology joins everything standing on the floor
    assert model.clusters("pos", min_size=MIN_CLUSTER_SIZE).max() == 0
    # each planar prism face is a normal cluster of its own
    for face in (DATA2_PRISM_RED_FACE, DATA2_PRISM_BROWN_FACE):
        face_labels = normal_clusters[node_truth == face]
        main = np.bincount(face_labels + 1).argmax() - 1
        assert main >= 0 and main != floor_cluster
        assert (face_labels == main).mean() > 0.5


@pytest.mark.parametrize("make_data", [make_data1, make_data2], ids=["data1", "data2"])
def test_colour_noise_is_the_stated_model_and_zero_is_flat(make_data):
    flat_positions, flat, labels = make_data(n_points=20_000, random_state=0, color_noise=0)
    positions, noisy, same_labels = make_data(n_points=20_000, random_state=0, color_noise=20.0)
    # the noise is drawn last: positions and labels do not depend on its level
    np.testing.assert_array_equal(positions, flat_positions)
    np.testing.assert_array_equal(labels, same_labels)
    for label in np.unique(labels):
        region = labels == label
        assert len(np.unique(flat[region], axis=0)) == 1  # one flat colour per region
        residual = noisy[region] - flat[region]
        inside = (flat[region] > 80) & (flat[region] < 175)  # channels clipping cannot reach
        if inside.any():
            assert residual[inside].std() == pytest.approx(20.0, rel=0.05)
            assert abs(residual[inside].mean()) < 1.0
    assert noisy.min() >= 0.0 and noisy.max() <= 255.0
    assert np.any(noisy == 255.0) or np.any(noisy == 0.0)  # clipped, not wrapped


def test_colour_noise_default_and_validation():
    from gngdt.eval.synthetic import COLOR_NOISE

    _, default, _ = make_data1(n_points=1_000, random_state=0)
    _, explicit, _ = make_data1(n_points=1_000, random_state=0, color_noise=COLOR_NOISE)
    np.testing.assert_array_equal(default, explicit)
    assert COLOR_NOISE > 0
    with pytest.raises(ValueError, match="color_noise"):
        make_data2(n_points=10, color_noise=-1.0)
    with pytest.raises(ValueError, match="color_noise"):
        make_data1(n_points=10, color_noise=float("nan"))
