"""Deprojection, voxel downsampling and the point cap, against hand-computed geometry."""

from __future__ import annotations

import numpy as np
import pytest

from gngdt.io.deproject import (
    Deprojector,
    cap_points,
    ray_map,
    uniform_subset,
    voxel_downsample,
)
from gngdt.io.frame import CameraIntrinsics, Frame

INTRINSICS = CameraIntrinsics(width=4, height=3, fx=2.0, fy=4.0, cx=1.5, cy=1.0)


def test_ray_map_is_pixel_offset_over_focal_length() -> None:
    rays = ray_map(INTRINSICS)
    assert rays.shape == (3, 4, 2)
    assert rays.dtype == np.float32
    # pixel (u=3, v=0): ((3 - 1.5) / 2, (0 - 1) / 4)
    np.testing.assert_allclose(rays[0, 3], [0.75, -0.25])
    np.testing.assert_allclose(rays[1, 0], [-0.75, 0.0])


def test_deprojection_of_known_pixels() -> None:
    depth = np.zeros((3, 4), dtype=np.uint16)
    depth[1, 0] = 2000  # u=0, v=1 at 2 m -> x = (0-1.5)/2*2 = -1.5, y = 0
    depth[2, 3] = 1000  # u=3, v=2 at 1 m -> x = 0.75, y = (2-1)/4 = 0.25
    color = np.zeros((3, 4, 3), dtype=np.uint8)
    color[1, 0] = (10, 20, 30)
    color[2, 3] = (200, 100, 50)
    positions, colors = Deprojector()(depth, color, INTRINSICS)
    np.testing.assert_allclose(positions, [[-1.5, 0.0, 2.0], [0.75, 0.25, 1.0]], atol=1e-6)
    np.testing.assert_array_equal(colors, [[10, 20, 30], [200, 100, 50]])
    assert positions.dtype == np.float32 and colors.dtype == np.uint8


def test_invalid_and_out_of_range_depths_are_dropped() -> None:
    depth = np.array([[0, 50, 500, 3000], [11000, 1000, 0, 0], [0, 0, 0, 0]], dtype=np.uint16)
    positions, _ = Deprojector(min_depth_m=0.1, max_depth_m=10.0)(depth, None, INTRINSICS)
    np.testing.assert_allclose(sorted(positions[:, 2]), [0.5, 1.0, 3.0])
    float_depth = depth.astype(np.float32)
    float_depth[0, 2] = np.nan
    positions, colors = Deprojector()(float_depth, None, INTRINSICS)
    assert colors is None
    np.testing.assert_allclose(sorted(positions[:, 2]), [1.0, 3.0])


def test_organized_deprojection_keeps_the_image_layout_with_nan_holes() -> None:
    depth = np.zeros((3, 4), dtype=np.uint16)
    depth[1, 0] = 2000
    depth[2, 3] = 1000
    deproject = Deprojector(min_depth_m=0.0, max_depth_m=float("inf"))
    points = deproject.organized(depth, INTRINSICS)
    assert points.shape == (3, 4, 3) and points.dtype == np.float32
    np.testing.assert_allclose(points[1, 0], [-1.5, 0.0, 2.0], atol=1e-6)
    np.testing.assert_allclose(points[2, 3], [0.75, 0.25, 1.0], atol=1e-6)
    holes = depth == 0
    assert np.isnan(points[holes]).all() and np.isfinite(points[~holes]).all()
    # the same points, in the same order, as the unorganized deprojection
    positions, _ = deproject(depth, None, INTRINSICS)
    np.testing.assert_array_equal(points[~holes], positions)


def test_organized_deprojection_applies_the_depth_range_and_checks_sizes() -> None:
    depth = np.array([[0, 50, 500, 3000], [11000, 1000, 0, 0], [0, 0, 0, 0]], dtype=np.uint16)
    points = Deprojector(min_depth_m=0.1, max_depth_m=10.0).organized(depth, INTRINSICS)
    np.testing.assert_allclose(np.sort(points[np.isfinite(points[..., 2]), 2]), [0.5, 1.0, 3.0])
    with pytest.raises(ValueError, match="does not match calibration"):
        Deprojector().organized(np.ones((5, 5), np.uint16), INTRINSICS)


def test_size_mismatch_is_a_clear_error() -> None:
    with pytest.raises(ValueError, match="does not match calibration"):
        Deprojector()(np.ones((5, 5), np.uint16), None, INTRINSICS)
    with pytest.raises(ValueError, match="depth range"):
        Deprojector(min_depth_m=2.0, max_depth_m=1.0)


def test_voxel_downsample_averages_each_occupied_voxel() -> None:
    positions = np.array(
        [[0.01, 0.01, 0.01], [0.03, 0.03, 0.03], [0.51, 0.01, 0.01], [-0.02, 0.0, 0.0]],
        dtype=np.float32,
    )
    colors = np.array([[0, 0, 0], [100, 50, 11], [7, 7, 7], [9, 9, 9]], dtype=np.uint8)
    merged, merged_colors = voxel_downsample(positions, colors, voxel_size_m=0.1)
    order = np.lexsort(merged.T[::-1])
    merged, merged_colors = merged[order], merged_colors[order]
    np.testing.assert_allclose(
        merged, [[-0.02, 0.0, 0.0], [0.02, 0.02, 0.02], [0.51, 0.01, 0.01]], atol=1e-6
    )
    np.testing.assert_array_equal(merged_colors, [[9, 9, 9], [50, 25, 6], [7, 7, 7]])
    with pytest.raises(ValueError, match="voxel size"):
        voxel_downsample(positions, colors, 0.0)


def test_cap_points_keeps_a_subset_of_the_given_size() -> None:
    positions = np.arange(300, dtype=np.float32).reshape(100, 3)
    colors = np.arange(300, dtype=np.uint8).reshape(100, 3)
    capped, capped_colors = cap_points(positions, colors, 10, np.random.default_rng(1))
    assert capped.shape == (10, 3)
    rows = (capped[:, 0] / 3).astype(int)
    assert len(set(rows)) == 10
    np.testing.assert_array_equal(capped_colors, colors[rows])
    same, _ = cap_points(positions, colors, 1000, np.random.default_rng(1))
    assert same is positions


def test_uniform_subset_draws_every_index_and_pair_equally_often() -> None:
    rng = np.random.default_rng(7)
    n, k, trials = 40, 8, 20_000
    included = np.zeros(n)
    both_first = 0
    for _ in range(trials):
        subset = uniform_subset(n, k, rng)
        assert subset.shape == (k,) and (np.diff(subset) > 0).all()
        assert subset[0] >= 0 and subset[-1] < n
        included[subset] += 1
        both_first += int(subset[0] == 0 and subset[1] == 1)
    share = included / trials  # k / n = 0.2 each; one standard deviation is 0.0028
    assert np.abs(share - k / n).max() < 0.015
    pair = k * (k - 1) / (n * (n - 1))
    assert abs(both_first / trials - pair) < 0.01
    with pytest.raises(ValueError, match="0 < k < n"):
        uniform_subset(5, 5, rng)


def test_a_capped_cloud_is_a_subset_of_the_full_cloud() -> None:
    from gngdt.io.deproject import CloudOptions, FrameToCloud

    # a slanted wall, every pixel its own colour, some pixels without depth
    height, width = 30, 40
    rng = np.random.default_rng(3)
    depth = (800 + 10 * np.arange(width)[None, :] + np.zeros((height, 1))).astype(np.uint16)
    depth[rng.random((height, width)) < 0.1] = 0
    color = rng.integers(0, 256, (height, width, 3), dtype=np.uint8)
    frame = Frame(0, 1, color, depth, CameraIntrinsics(width, height, 50.0, 50.0, 20.0, 15.0))
    full_positions, full_colors = FrameToCloud(CloudOptions())(frame)
    positions, colors = FrameToCloud(CloudOptions(max_points=500))(frame)
    assert positions.shape == (500, 3) and colors.shape == (500, 3)
    full = {tuple(row) for row in np.hstack([full_positions, full_colors.astype(np.float32)])}
    assert all(tuple(row) in full for row in np.hstack([positions, colors.astype(np.float32)]))
    assert len({tuple(row) for row in positions}) == 500


def test_a_voxel_too_small_for_the_extent_is_refused_not_wrapped() -> None:
    positions = np.array([[0.0, 0.0, 0.0], [1000.0, 1000.0, 1000.0]], dtype=np.float32)
    with pytest.raises(ValueError, match="too small"):
        voxel_downsample(positions, None, 1e-6)


def test_uniform_subset_drawn_in_blocks_is_one_draw(monkeypatch: pytest.MonkeyPatch) -> None:
    """The random numbers are drawn a block at a time: the same subset (and the generator left
    in the same state) whatever the block, so clouds stay the same draw for draw."""
    import gngdt.io.deproject as deproject

    whole = np.random.default_rng(5)
    expected = uniform_subset(10_007, 600, whole)
    monkeypatch.setattr(deproject, "SUBSET_BLOCK", 1000)
    blocks = np.random.default_rng(5)
    np.testing.assert_array_equal(uniform_subset(10_007, 600, blocks), expected)
    assert blocks.integers(1 << 62) == whole.integers(1 << 62)
