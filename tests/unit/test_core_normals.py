"""Normals beyond the paper (off by default): an angle threshold and fresh normals."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gngdt.core import GNGDT
from gngdt.core.kernels.normals import smallest_eigenvector


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


def random_symmetric(rng: np.random.Generator, eigenvalues: np.ndarray) -> np.ndarray:
    """A symmetric 3x3 matrix with these eigenvalues, in a random orientation."""
    rotation, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    return rotation @ np.diag(eigenvalues) @ rotation.T


@pytest.mark.parametrize("spectrum", [
    "surface",  # a covariance of points on a surface: the smallest root far below the others
    "edge",  # two small roots, well apart
    "blob",  # three roots within 1 % of each other: Newton's steps are slow, the closed form ends
    "indefinite",  # not a covariance: the closed form alone
])
def test_the_smallest_eigenvector_is_eighs(spectrum: str) -> None:
    rng = np.random.default_rng(6)
    for _ in range(200):
        scale = 10.0 ** rng.uniform(-6, 3)
        eigenvalues = {
            "surface": [rng.uniform(0, 1e-4), rng.uniform(0.3, 1), rng.uniform(1, 2)],
            "edge": [rng.uniform(0, 0.01), rng.uniform(0.05, 0.1), rng.uniform(1, 2)],
            "blob": [1.0, 1.004, 1.009],
            "indefinite": [rng.uniform(-2, -1), rng.uniform(0, 1), rng.uniform(1, 2)],
        }[spectrum]
        matrix = random_symmetric(rng, scale * np.array(eigenvalues))
        *vector, ok = smallest_eigenvector(*matrix[np.triu_indices(3)])
        assert ok
        expected = np.linalg.eigh(matrix)[1][:, 0]
        assert min(np.linalg.norm(vector - expected),
                   np.linalg.norm(vector + expected)) < 1e-6, (spectrum, eigenvalues)
