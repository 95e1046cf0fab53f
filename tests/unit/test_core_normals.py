"""Normals beyond the paper (off by default): an angle threshold and fresh normals."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gngdt.core import GNGDT


def curved_surface(rng: np.random.Generator, count: int = 20_000) -> np.ndarray:
    """A quarter cylinder (radius 0.2 m) standing in front of the sensor: normals keep turning."""
    angle = rng.uniform(0.0, math.pi / 2, count)
    height = rng.uniform(-0.2, 0.2, count)
    return np.column_stack([0.2 * np.cos(angle), height, 1.0 - 0.2 * np.sin(angle)])


def sign_invariant_angles(normals: np.ndarray, edges: np.ndarray) -> np.ndarray:
    cosine = np.abs(np.einsum("ij,ij->i", normals[edges[:, 0]], normals[edges[:, 1]]))
    return np.degrees(np.arccos(np.clip(cosine, 0.0, 1.0)))


def test_an_angle_threshold_is_the_chord_threshold_it_names() -> None:
    points = curved_surface(np.random.default_rng(0))
    by_angle = GNGDT(max_nodes=200, normal_angle_deg=6.0, random_state=1).fit(points,
                                                                              n_steps=20_000)
    by_chord = GNGDT(max_nodes=200, tau_nor=2 * math.sin(math.radians(3.0)),
                     random_state=1).fit(points, n_steps=20_000)
    assert np.array_equal(by_angle.edges("nor"), by_chord.edges("nor"))
    assert np.array_equal(by_angle.positions_, by_chord.positions_)


def test_refreshed_normals_are_fresh_and_their_edges_follow_the_angle() -> None:
    points = curved_surface(np.random.default_rng(2))
    model = GNGDT(max_nodes=300, normal_angle_deg=8.0, normal_refresh_steps=1_000,
                  random_state=3).fit(points, n_steps=30_000)
    # a restored copy does not know its normals are fresh: it computes eq. 16 again
    recomputed = GNGDT.from_state(model.get_state()).fresh_normals()
    assert np.array_equal(model.normals_, recomputed)
    assert np.array_equal(model.fresh_normals(), recomputed)
    pos_edges = model.edges("pos")
    defined = np.linalg.norm(model.normals_, axis=1) > 0
    both = defined[pos_edges[:, 0]] & defined[pos_edges[:, 1]]
    expected = pos_edges[both & (sign_invariant_angles(model.normals_, pos_edges) < 8.0)]
    assert {tuple(e) for e in model.edges("nor")} == {tuple(e) for e in expected}


def test_without_refresh_stored_normals_lag_behind() -> None:
    # the paper's behaviour, kept by default: only each step's winner gets a new normal
    points = curved_surface(np.random.default_rng(4))
    model = GNGDT(max_nodes=300, random_state=5).fit(points, n_steps=30_000)
    assert not np.array_equal(model.normals_, model.fresh_normals())


@pytest.mark.parametrize("bad", [0.0, 91.0, float("nan")])
def test_normal_angle_is_validated(bad: float) -> None:
    with pytest.raises(ValueError, match="normal_angle_deg"):
        GNGDT(normal_angle_deg=bad).check_params()


def test_normal_refresh_steps_is_validated() -> None:
    with pytest.raises(ValueError, match="normal_refresh_steps"):
        GNGDT(normal_refresh_steps=0).check_params()
