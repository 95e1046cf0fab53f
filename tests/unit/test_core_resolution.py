"""A map that grows with the world (`GNGDT`'s ``resolution_m``, `gngdt.core.gas.coverage`): the node
budget follows the surface seen, new surface gets nodes as soon as it is seen, ``max_nodes``
stays the cap, and without ``resolution_m`` nothing changes."""

from __future__ import annotations

import numpy as np
import pytest

from gngdt.core import GNGDT
from gngdt.core.gas.coverage import SurfaceCoverage


def wall(rng: np.random.Generator, width: float, height: float, count: int = 20_000,
         depth: float = 2.0) -> np.ndarray:
    """Points (N, 3) float32 of a flat wall ``depth`` metres in front of the camera."""
    xy = rng.random((count, 2)) * [width, height] - [width / 2, height / 2]
    return np.column_stack([xy, np.full(count, depth)]).astype(np.float32)


def shifted(x: float) -> np.ndarray:
    """A camera pose (4, 4) moved ``x`` metres sideways."""
    pose = np.eye(4)
    pose[0, 3] = x
    return pose


def test_coverage_counts_the_cells_a_surface_crosses() -> None:
    rng = np.random.default_rng(0)
    coverage = SurfaceCoverage(0.1)
    # a 2 x 1 m wall (cell-aligned corner) crosses 20 x 10 cells
    points = np.column_stack([rng.random((30_000, 2)) * [1.999, 0.999],
                              np.full(30_000, 2.05)]).astype(np.float32)
    assert coverage.add(points) == 200 and coverage.count == 200
    assert coverage.add(points) == 0  # seen again: nothing new
    assert coverage.add(points, shifted(1.0)) == 100  # half of it is new surface
    centres = coverage.centres()
    assert centres.shape == (300, 3) and np.allclose(centres[:, 2], 2.05)
    assert centres[:, 0].min() == pytest.approx(0.05) and centres[:, 0].max() == pytest.approx(2.95)
    restored = SurfaceCoverage(0.1)
    restored.restore(coverage.cells())
    assert restored.count == 300 and restored.add(points) == 0
    with pytest.raises(ValueError, match="distinct"):
        restored.restore(np.array([3, 3]))


def test_coverage_grows_its_table_and_skips_non_finite_points() -> None:
    rng = np.random.default_rng(1)
    coverage = SurfaceCoverage(0.01)
    points = (rng.random((50_000, 3)) * 4.0).astype(np.float32)  # ~50,000 distinct cells
    points[::7] = np.nan
    added = coverage.add(points)
    expected = np.unique(np.floor(points[np.isfinite(points).all(axis=1)] / 0.01), axis=0)
    assert added == coverage.count == len(expected)
    assert len(coverage.keys) >= 2 * coverage.count


def test_the_budget_follows_the_surface_seen_and_max_nodes_caps_it() -> None:
    rng = np.random.default_rng(2)
    model = GNGDT(max_nodes=500, lambda_=50, resolution_m=0.1, random_state=0)
    points = wall(rng, 1.5, 1.0)
    model.partial_fit(points, n_steps=40_000, camera_pose=shifted(0.0))
    first_view = model.growth_limit_
    assert 140 <= first_view <= 170  # 15 x 10 cells, a few more where the wall straddles two
    assert model.n_nodes_ == first_view  # grown to the budget, not beyond
    model.partial_fit(points, n_steps=40_000, camera_pose=shifted(0.0))
    assert model.n_nodes_ == first_view  # the same view again: no new surface, no new node
    model.partial_fit(points, n_steps=40_000, camera_pose=shifted(1.5))
    assert model.growth_limit_ >= 2 * first_view - 10 and model.n_nodes_ == model.growth_limit_
    model.partial_fit(points, n_steps=100_000, camera_pose=shifted(3.0))
    model.partial_fit(points, n_steps=100_000, camera_pose=shifted(4.5))
    assert model.growth_limit_ == model.n_nodes_ == 500  # the cap


def test_new_surface_gets_nodes_as_soon_as_it_is_seen() -> None:
    """A wall coming into view 1.5 m beside the map: within 2,000 steps (four insertions of a
    fixed budget's lambda) it is covered to the resolution, whereas a fixed budget's network
    leaves most of it farther than that from every node."""
    rng = np.random.default_rng(3)
    points = wall(rng, 1.5, 1.0)
    moved = points @ shifted(1.5)[:3, :3].T + shifted(1.5)[:3, 3]
    for resolution, covered in ((0.1, True), (None, False)):
        model = GNGDT(max_nodes=1000, lambda_=500, resolution_m=resolution, random_state=0)
        model.partial_fit(points, n_steps=60_000, camera_pose=shifted(0.0))
        model.partial_fit(points, n_steps=2_000, camera_pose=shifted(1.5))
        _, distance = model.predict(moved, return_distance=True)
        far = np.mean(distance > 0.1)
        assert (far < 0.02) if covered else (far > 0.3), (resolution, far)


def test_without_resolution_the_budget_is_max_nodes() -> None:
    rng = np.random.default_rng(4)
    points = wall(rng, 1.5, 1.0)
    plain = GNGDT(max_nodes=80, random_state=0).fit(points, n_steps=50_000,
                                                    camera_pose=shifted(0.5))
    off = GNGDT(max_nodes=80, resolution_m=0, random_state=0).fit(points, n_steps=50_000,
                                                                  camera_pose=shifted(0.5))
    assert plain.growth_limit_ == plain.n_nodes_ == 80
    assert off.check_params()["resolution_m"] is None  # 0 turns it off, as TOML has no None
    np.testing.assert_array_equal(plain.positions_, off.positions_)


def test_a_checkpoint_keeps_the_surface_seen() -> None:
    rng = np.random.default_rng(5)
    points = wall(rng, 1.5, 1.0)
    model = GNGDT(max_nodes=400, lambda_=50, resolution_m=0.1, random_state=0)
    model.partial_fit(points, n_steps=20_000, camera_pose=shifted(0.0))
    restored = GNGDT.from_state(model.get_state())
    assert restored.growth_limit_ == model.growth_limit_
    for network in (model, restored):
        network.partial_fit(points, n_steps=5_000, camera_pose=shifted(0.7))
    np.testing.assert_array_equal(restored.positions_, model.positions_)
    assert restored.growth_limit_ == model.growth_limit_
