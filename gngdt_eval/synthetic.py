"""The paper's synthetic data sets (Section 3.1, Figure 7) with ground-truth labels.

Positions are multiplied by the scale factor ``scl``; colours stay on the 0-255 scale.

Colour model: each region has one base colour, and every point's colour is that base colour plus
independent Gaussian noise of standard deviation ``color_noise`` on each of R, G and B, clipped to
0-255 (a camera's within-region variation: shading, texture, sensor noise). ``color_noise=0``
gives flat colours. The noise is drawn after everything else, so positions and labels do not
depend on the level. The default level is the one that best reproduces the paper's Tables 2-3 for
GNG and GNG-W (``gngdt eval paper``; see gngdt_eval/README.md).
"""

from __future__ import annotations

import numpy as np

RED = (255.0, 0.0, 0.0)
GREEN = (0.0, 255.0, 0.0)

DATA1_SIDE = 300.0
# C1..C4 of the paper; label i is the rectangle centred at DATA1_CENTRES[i]
DATA1_CENTRES = np.array([[75.0, 75.0], [225.0, 75.0], [75.0, 225.0], [225.0, 225.0]])
DATA1_COLOURS = np.array([RED, GREEN, GREEN, RED])  # a checkerboard

# Data2 geometry (the paper shows it only in Figure 7b; these are our choices, in the same units
# as Data1): a 300 x 300 brown floor at z = 0; half of a square ("quadratic") prism, i.e. the two
# side faces that face -x and -y, 80 wide and 100 tall, one red and one brown (the brown face
# shares the floor's colour, as in the paper's colour clustering); half of a red cylinder
# (radius 40, height 100), the side facing -y. Top faces are not sampled, and floor points under
# the objects' footprints are left out. Points are uniform in area.
DATA2_FLOOR = 0
DATA2_PRISM_RED_FACE = 1
DATA2_PRISM_BROWN_FACE = 2
DATA2_CYLINDER = 3
DATA2_RED = (200.0, 30.0, 30.0)
DATA2_BROWN = (140.0, 90.0, 50.0)
PRISM_MIN = np.array([50.0, 110.0])  # the prism's footprint is [50, 130] x [110, 190]
PRISM_SIDE = 80.0
CYLINDER_CENTRE = np.array([210.0, 150.0])
CYLINDER_RADIUS = 40.0
OBJECT_HEIGHT = 100.0

#: default standard deviation of the per-channel colour noise (0-255 units), both data sets: the
#: level whose GNG and GNG-W best reproduce the paper's Tables 2-3 (a grid of 0-30, see
#: gngdt_eval/README.md)
COLOR_NOISE = 3.0


def make_data1(
    scl: float = 1.0,
    n_points: int = 10_000,
    random_state: int | np.random.Generator | None = None,
    color_noise: float = COLOR_NOISE,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Data1: uniform points in a 300 x 300 square of four 150 x 150 red/green rectangles.

    Returns positions (N, 2) float64 (times ``scl``), colors (N, 3) float64 in 0-255 (base colour
    plus ``color_noise``, see the module docstring), labels (N,) int64 rectangle index 0..3
    (centres ``DATA1_CENTRES * scl``).
    """
    _check(scl, n_points, color_noise)
    rng = np.random.default_rng(random_state)
    positions = rng.uniform(0.0, DATA1_SIDE, size=(n_points, 2))
    labels = (positions[:, 0] >= 150.0).astype(np.int64) + 2 * (positions[:, 1] >= 150.0)
    colors = _add_noise(rng, DATA1_COLOURS[labels], color_noise)
    return positions * scl, colors, labels


def make_data2(
    scl: float = 1.0,
    n_points: int = 112_500,
    random_state: int | np.random.Generator | None = None,
    color_noise: float = COLOR_NOISE,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Data2: a half square prism and a half cylinder standing on a floor (see module docstring).

    Returns positions (N, 3) float64 (times ``scl``), colors (N, 3) float64 in 0-255 (base colour
    plus ``color_noise``), labels (N,) int64: ``DATA2_FLOOR``, ``DATA2_PRISM_RED_FACE``,
    ``DATA2_PRISM_BROWN_FACE``, ``DATA2_CYLINDER``.
    """
    _check(scl, n_points, color_noise)
    rng = np.random.default_rng(random_state)
    face_area = PRISM_SIDE * OBJECT_HEIGHT
    cylinder_area = np.pi * CYLINDER_RADIUS * OBJECT_HEIGHT
    floor_area = DATA1_SIDE**2 - PRISM_SIDE**2 - np.pi * CYLINDER_RADIUS**2
    areas = np.array([floor_area, face_area, face_area, cylinder_area])
    counts = rng.multinomial(n_points, areas / areas.sum())
    parts = [
        _floor(rng, counts[0]),
        _prism_face(rng, counts[1], axis=1),  # the red face at y = 110, facing -y
        _prism_face(rng, counts[2], axis=0),  # the brown face at x = 50, facing -x
        _half_cylinder(rng, counts[3]),
    ]
    colours = (DATA2_BROWN, DATA2_RED, DATA2_BROWN, DATA2_RED)
    positions = np.concatenate(parts)
    labels = np.repeat(np.arange(4, dtype=np.int64), counts)
    colors = np.repeat(np.array(colours), counts, axis=0)
    shuffle = rng.permutation(n_points)
    colors = _add_noise(rng, colors[shuffle], color_noise)
    return positions[shuffle] * scl, colors, labels[shuffle]


def _check(scl: float, n_points: int, color_noise: float) -> None:
    if not np.isfinite(scl) or scl <= 0:
        raise ValueError(f"scl must be a positive finite number, got {scl!r}")
    if n_points < 1:
        raise ValueError(f"n_points must be >= 1, got {n_points!r}")
    if not np.isfinite(color_noise) or color_noise < 0:
        raise ValueError(f"color_noise must be a finite number >= 0, got {color_noise!r}")


def _add_noise(rng: np.random.Generator, colors: np.ndarray, color_noise: float) -> np.ndarray:
    """colors (N, 3) 0-255 plus N(0, color_noise^2) per channel, clipped; a copy."""
    if color_noise == 0:
        return np.array(colors, dtype=np.float64)
    noisy = colors + rng.normal(0.0, color_noise, size=colors.shape)
    return np.clip(noisy, 0.0, 255.0)


def _floor(rng: np.random.Generator, count: int) -> np.ndarray:
    """Uniform floor points outside the objects' footprints (rejection sampling)."""
    kept: list[np.ndarray] = []
    remaining = count
    while remaining > 0:
        xy = rng.uniform(0.0, DATA1_SIDE, size=(2 * remaining + 16, 2))
        in_prism = np.all((xy >= PRISM_MIN) & (xy <= PRISM_MIN + PRISM_SIDE), axis=1)
        in_cylinder = np.linalg.norm(xy - CYLINDER_CENTRE, axis=1) <= CYLINDER_RADIUS
        xy = xy[~(in_prism | in_cylinder)][:remaining]
        kept.append(xy)
        remaining -= len(xy)
    xy = np.concatenate(kept)
    return np.column_stack([xy, np.zeros(len(xy))])


def _prism_face(rng: np.random.Generator, count: int, axis: int) -> np.ndarray:
    """The prism face lying in the plane ``coordinate[axis] = PRISM_MIN[axis]``."""
    along = PRISM_MIN[1 - axis] + rng.uniform(0.0, PRISM_SIDE, size=count)
    height = rng.uniform(0.0, OBJECT_HEIGHT, size=count)
    points = np.empty((count, 3))
    points[:, axis] = PRISM_MIN[axis]
    points[:, 1 - axis] = along
    points[:, 2] = height
    return points


def _half_cylinder(rng: np.random.Generator, count: int) -> np.ndarray:
    """The half of the cylinder's side facing -y (angles pi..2pi)."""
    angle = rng.uniform(np.pi, 2.0 * np.pi, size=count)
    height = rng.uniform(0.0, OBJECT_HEIGHT, size=count)
    return np.column_stack([
        CYLINDER_CENTRE[0] + CYLINDER_RADIUS * np.cos(angle),
        CYLINDER_CENTRE[1] + CYLINDER_RADIUS * np.sin(angle),
        height,
    ])
