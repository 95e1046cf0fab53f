"""Real frames damaged as a structured-light camera damages them, for ``gngdt eval
segmentation --damage-depth SEED``: the same labelled scenes, with depth dropped where such a
camera loses it, so the effect of missing depth on segments is measured on real scenes.

A structured-light camera (a projected pattern seen by an offset camera: Kinect v1, Asus Xtion,
RealSense F200/SR300, industrial bin-picking cameras) loses depth

- in **stripes**: bands of rows (and, fewer, of columns) where the pattern could not be decoded,
  one to a few pixels wide, running across much of the image;
- at **depth edges**: the projector's shadow on the far surface beside a nearer one (on one side
  of the near object, the projector's), and a pixel or two on both sides of every jump;
- on **dark and glossy spots**: dark surfaces return too little of the pattern, glossy ones
  mirror it away (saturated colour), and small specular spots anywhere.

`DepthDamage` holds how much of each; `damage_depth` applies it to one depth image, seeded per
frame (the same seed and frame index always drop the same pixels). Ground truth is unchanged;
the score counts only pixels that keep their depth (a label set from such a camera marks the
others 0).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import asdict, dataclass, replace

import numpy as np

from gngdt.io.frame import Frame
from gngdt.io.sources.base import FrameSource

#: pixels: the size (Gaussian sigma) of the patches in which dark surfaces lose their depth
BLOB_PX = 3.0


@dataclass(frozen=True)
class DepthDamage:
    """How much depth a structured-light camera loses (`damage_depth`); sizes in pixels of the
    frame's depth image."""

    #: share of the rows that lie in missing stripes ...
    row_share: float = 0.12
    #: ... and of the columns
    column_share: float = 0.03
    #: a stripe is 1 to this many pixels wide ...
    max_stripe_px: int = 4
    #: ... and spans a random run of this share (up to all) of the image's width (height)
    min_stripe_length: float = 0.3
    #: a depth jump larger than this share of the nearer depth is a depth edge
    edge_ratio: float = 0.03
    #: pixels of the far surface lost beside a nearer one, on the projector's side (the right)
    shadow_px: int = 6
    #: pixels lost on both sides of every depth edge
    edge_px: int = 1
    #: pixels darker than this (grey 0-255) lose their depth, in patches, with probability
    #: ``dark_drop``
    dark_below: int = 25
    dark_drop: float = 0.5
    #: pixels brighter than this (grey, saturated: glossy) lose their depth
    glossy_above: int = 250
    #: specular spots per frame, each a disc of 2 to ``max_spot_px`` pixels' radius
    spots: int = 12
    max_spot_px: int = 10

    def __post_init__(self) -> None:
        shares = (self.row_share, self.column_share, self.min_stripe_length, self.edge_ratio,
                  self.dark_drop)
        if not all(0.0 <= share <= 1.0 for share in shares):
            raise ValueError("shares and probabilities must be within [0, 1]")
        if min(self.max_stripe_px, self.max_spot_px) < 1 or min(
                self.shadow_px, self.edge_px, self.spots) < 0:
            raise ValueError("stripe and spot sizes must be >= 1, shadows, edges, spots >= 0")

    def as_dict(self) -> dict[str, float]:
        return asdict(self)

    def describe(self) -> str:
        return (f"structured-light damage: {self.row_share:.0%} of rows and "
                f"{self.column_share:.0%} of columns in stripes 1-{self.max_stripe_px} px wide; "
                f"{self.shadow_px} px shadows beside nearer surfaces, {self.edge_px} px at every "
                f"depth edge (> {self.edge_ratio:.0%}); dark (< {self.dark_below}) pixels lost "
                f"with p = {self.dark_drop}, glossy (> {self.glossy_above}) always; {self.spots} "
                f"specular spots up to {self.max_spot_px} px")


def damage_depth(depth: np.ndarray, color: np.ndarray, damage: DepthDamage,
                 rng: np.random.Generator) -> np.ndarray:
    """(H, W) ``depth`` (any dtype, 0 = no measurement) with the pixels ``damage`` drops set to
    0; color: (H, W, 3) uint8 RGB of the same pixels; rng draws the stripes and spots."""
    lost = _stripes(depth.shape, damage.row_share, damage, rng)
    lost |= _stripes(depth.shape[::-1], damage.column_share, damage, rng).T
    lost |= _edge_holes(depth.astype(np.float64), damage)
    grey = color.astype(np.float64) @ np.array([0.299, 0.587, 0.114])
    lost |= (grey < damage.dark_below) & (_blobs(depth.shape, rng) < damage.dark_drop)
    lost |= grey > damage.glossy_above
    lost |= _spots(depth.shape, damage, rng)
    return np.where(lost, 0, depth).astype(depth.dtype)


def _stripes(shape: tuple[int, int], share: float, damage: DepthDamage,
             rng: np.random.Generator) -> np.ndarray:
    """(rows, columns) bool: stripes 1 to ``max_stripe_px`` rows wide, each over a random run
    of the columns, until ``share`` of the rows lie in one."""
    rows, columns = shape
    lost = np.zeros(shape, dtype=bool)
    striped = np.zeros(rows, dtype=bool)
    while striped.sum() < round(share * rows):
        width = int(rng.integers(1, damage.max_stripe_px + 1))
        top = int(rng.integers(0, rows - width + 1))
        length = round(columns * rng.uniform(damage.min_stripe_length, 1.0))
        left = int(rng.integers(0, columns - length + 1))
        lost[top:top + width, left:left + length] = True
        striped[top:top + width] = True
    return lost


def _edge_holes(depth: np.ndarray, damage: DepthDamage) -> np.ndarray:
    """(H, W) bool: ``edge_px`` pixels on both sides of every depth jump, and the projector's
    shadow: pixels with a nearer surface within ``shadow_px`` to their left."""
    from scipy import ndimage

    measured = depth > 0
    lost = np.zeros(depth.shape, dtype=bool)
    near = np.where(measured, depth, np.inf)
    for axis in (0, 1) if damage.edge_px > 0 else ():
        a = np.take(near, np.arange(near.shape[axis] - 1), axis=axis)
        b = np.take(near, np.arange(1, near.shape[axis]), axis=axis)
        both = np.isfinite(a) & np.isfinite(b)
        jump = np.zeros(a.shape, dtype=bool)
        jump[both] = np.abs(a[both] - b[both]) > damage.edge_ratio * np.minimum(a[both],
                                                                                b[both])
        pad = [(0, 0), (0, 0)]
        pad[axis] = (0, 1)
        lost |= np.pad(jump, pad)
        pad[axis] = (1, 0)
        lost |= np.pad(jump, pad)
    if damage.edge_px > 1:
        lost = ndimage.binary_dilation(lost, iterations=damage.edge_px - 1)
    lost &= measured
    # a nearer surface within shadow_px to the left hides this pixel from the projector
    nearest_left = np.full(depth.shape, np.inf)
    for shift in range(1, damage.shadow_px + 1):
        nearest_left[:, shift:] = np.minimum(nearest_left[:, shift:], near[:, :-shift])
    return lost | (measured & (nearest_left < depth * (1.0 - damage.edge_ratio)))


def _blobs(shape: tuple[int, int], rng: np.random.Generator) -> np.ndarray:
    """(H, W) values uniform in [0, 1] over the image but alike within blobs of a few pixels
    (`BLOB_PX`): a dark surface loses its depth in patches, not pixel by pixel."""
    from scipy import ndimage

    field = ndimage.gaussian_filter(rng.standard_normal(shape), BLOB_PX)
    ranks = np.empty(field.size)
    ranks[np.argsort(field, axis=None)] = np.arange(field.size)
    return (ranks / max(field.size - 1, 1)).reshape(shape)


def _spots(shape: tuple[int, int], damage: DepthDamage, rng: np.random.Generator) -> np.ndarray:
    """(H, W) bool: ``spots`` discs of random place and radius (specular highlights)."""
    rows, columns = np.ogrid[:shape[0], :shape[1]]
    lost = np.zeros(shape, dtype=bool)
    for _ in range(damage.spots):
        radius = rng.uniform(2.0, max(damage.max_spot_px, 2))
        row, column = rng.uniform(0, shape[0]), rng.uniform(0, shape[1])
        lost |= (rows - row) ** 2 + (columns - column) ** 2 <= radius * radius
    return lost


class DamagedSource(FrameSource):
    """Another source's frames with `damage_depth` applied, seeded by ``seed`` and each frame's
    index (every pass over the frames drops the same pixels)."""

    def __init__(self, source: FrameSource, damage: DepthDamage, seed: int) -> None:
        super().__init__(source.path, source.camera_note)
        self.source, self.damage, self.seed = source, damage, seed
        self.format = source.format

    def frames(self) -> Iterator[tuple[str, Frame]]:
        for name, frame in self.source.frames():
            rng = np.random.default_rng([self.seed, frame.index])
            yield name, replace(frame, depth=damage_depth(frame.depth, frame.color, self.damage,
                                                          rng))

    def describe(self) -> str:
        return f"{self.source.describe()}, {self.damage.describe()}, seed {self.seed}"
