"""References (k-means, voxel grid, DBSCAN) and report helpers on data with known answers."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from gngdt.eval.baselines import (
    dbscan_labels,
    kmeans_reference,
    quantization_error,
    voxel_grid_reference,
)
from gngdt.eval.report import format_mean_std, markdown_table, mean_std, write_report


def _grid_points(cells_per_axis: int, points_per_cell: int, seed: int = 0) -> np.ndarray:
    """Points jittered tightly around the centres of a unit-spaced 2D grid: (N, 2) float64."""
    rng = np.random.default_rng(seed)
    centres = (
        np.stack(
            np.meshgrid(np.arange(cells_per_axis), np.arange(cells_per_axis)), axis=-1
        ).reshape(-1, 2)
        + 0.5
    )
    return np.repeat(centres, points_per_cell, axis=0) + rng.normal(
        0, 0.01, (len(centres) * points_per_cell, 2)
    )


def test_quantization_error_is_rms_distance_to_nearest_representative() -> None:
    points = np.array([[0.0, 0.0], [3.0, 0.0], [10.0, 0.0]])
    colours = np.array([[0.0, 0, 0], [0, 0, 0], [30, 40, 0]])
    representatives = np.array([[0.0, 0.0], [10.0, 1.0]])
    error = quantization_error(points, colours, representatives, np.zeros((2, 3)))
    # distances 0, 3, 1 -> sqrt(10/3); colour offsets 0, 0, 50 -> sqrt(2500/3)
    assert error["pos"] == pytest.approx(math.sqrt(10 / 3))
    assert error["col"] == pytest.approx(math.sqrt(2500 / 3))


def test_kmeans_finds_well_separated_centres() -> None:
    points = _grid_points(4, 50)
    result = kmeans_reference(points, None, 16, random_state=1)
    assert result.positions.shape == (16, 2)
    assert result.quantization_error["pos"] < 0.05  # jitter is 0.01 per axis
    assert "col" not in result.quantization_error


def test_kmeans_colours_are_mean_colours_of_won_points() -> None:
    points = np.array([[0.0, 0.0], [0.0, 0.1], [5.0, 5.0], [5.0, 5.1]])
    colours = np.array([[0.0, 0, 0], [20, 0, 0], [100, 100, 100], [100, 100, 120]])
    result = kmeans_reference(points, colours, 2, random_state=0)
    order = np.argsort(result.positions[:, 0])
    np.testing.assert_allclose(result.colors[order], [[10, 0, 0], [100, 100, 110]])


def test_voxel_grid_reaches_the_requested_count_on_a_grid() -> None:
    points = _grid_points(10, 5)
    result = voxel_grid_reference(points, None, 100)
    assert result.positions.shape[0] == 100
    assert result.quantization_error["pos"] < 0.05


def test_voxel_grid_rejects_bad_counts() -> None:
    with pytest.raises(ValueError, match="n_points"):
        voxel_grid_reference(_grid_points(2, 2), None, 0)


def test_dbscan_separates_distant_blobs() -> None:
    rng = np.random.default_rng(3)
    blobs = np.concatenate([rng.normal(0, 0.05, (200, 3)), rng.normal(5, 0.05, (200, 3))])
    labels, eps = dbscan_labels(blobs, min_samples=5)
    assert eps > 0
    assert len(set(labels[:200]) - {-1}) == 1 and len(set(labels[200:]) - {-1}) == 1
    assert labels[0] != labels[-1]


def test_mean_std_ignores_non_finite_and_formats() -> None:
    stats = mean_std([1.0, 3.0, float("nan")])
    assert stats == {"mean": 2.0, "std": 1.0, "n": 2}
    assert format_mean_std(stats) == "2.000 ± 1.000"
    assert format_mean_std(mean_std([])) == "—"


def test_write_report_is_strict_json_and_markdown(tmp_path) -> None:
    table = markdown_table(["a", "b"], [[1, "x|y"]])
    assert table.splitlines()[2] == "| 1 | x\\|y |"
    md, js = write_report(
        tmp_path / "out",
        "r",
        "# T\n\n" + table,
        {"v": np.float32(1.5), "n": float("nan"), "a": np.arange(3)},
    )
    assert md.read_text().startswith("# T")
    assert json.loads(js.read_text()) == {"v": 1.5, "n": None, "a": [0, 1, 2]}


def test_topology_drawing_copes_with_no_edges(tmp_path) -> None:
    from gngdt.eval.plots import TopologyPanel, plot_topology_grid

    panels = [
        [
            TopologyPanel("3D", np.eye(3), np.empty((0, 2), np.int64), np.array([0, -1, 1])),
            TopologyPanel("2D", np.eye(2), np.empty((0, 2), np.int64), np.array([0, 0])),
        ]
    ]
    assert plot_topology_grid(panels, tmp_path / "t.png").stat().st_size > 1000
