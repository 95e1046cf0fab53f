"""Real frames damaged as a structured-light camera damages them (gngdt.eval.segmentation_damage,
``gngdt eval segmentation --damage-depth SEED``)."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from gngdt.eval.segmentation import SegmentationEvalSettings, evaluate_segmentation
from gngdt.eval.segmentation_damage import DamagedSource, DepthDamage, damage_depth
from gngdt.io.sources import open_source
from gngdt.services.cli import main as gngdt

HEIGHT, WIDTH = 60, 80
SMALL_PROFILE = """
[gngdt]
max_nodes = 200
lambda = 50

[frames]
steps_first_frame = 6000
steps_per_frame = 1000
"""


def scene() -> tuple[np.ndarray, np.ndarray]:
    """A wall 1.0 m away (grey) with a box 0.8 m away in front of it (columns 30-49, rows
    20-39, red): depth (H, W) uint16 millimetres and colour (H, W, 3)."""
    depth = np.full((HEIGHT, WIDTH), 1000, dtype=np.uint16)
    depth[20:40, 30:50] = 800
    color = np.full((HEIGHT, WIDTH, 3), 128, dtype=np.uint8)
    color[20:40, 30:50] = (200, 40, 40)
    return depth, color


def only(**values: float) -> DepthDamage:
    """Damage of one kind: everything else off."""
    none = {"row_share": 0.0, "column_share": 0.0, "shadow_px": 0, "edge_px": 0,
            "dark_below": 0, "glossy_above": 255, "spots": 0}
    return DepthDamage(**{**none, **values})


def test_the_same_seed_drops_the_same_pixels_and_never_adds_depth() -> None:
    depth, color = scene()
    first = damage_depth(depth, color, DepthDamage(), np.random.default_rng([3, 0]))
    again = damage_depth(depth, color, DepthDamage(), np.random.default_rng([3, 0]))
    other = damage_depth(depth, color, DepthDamage(), np.random.default_rng([4, 0]))
    assert first.dtype == depth.dtype
    assert np.array_equal(first, again) and not np.array_equal(first, other)
    kept = first > 0
    assert np.array_equal(first[kept], depth[kept])  # what is left is as measured
    assert 0.3 < kept.mean() < 0.95


def test_stripes_drop_runs_of_rows_and_columns() -> None:
    depth, color = scene()
    damaged = damage_depth(depth, color, only(row_share=0.2, max_stripe_px=3,
                                              min_stripe_length=1.0),
                           np.random.default_rng(0))
    empty_rows = (damaged == 0).all(axis=1)
    assert empty_rows.sum() >= round(0.2 * HEIGHT)
    assert ((damaged == 0) == empty_rows[:, None]).all()  # whole rows, nothing else
    columns = damage_depth(depth, color, only(column_share=0.1, min_stripe_length=1.0),
                           np.random.default_rng(0))
    assert (columns == 0).all(axis=0).any() and not (columns == 0).all(axis=1).any()


def test_the_projector_shadow_lies_right_of_a_nearer_surface_on_the_far_one() -> None:
    depth, color = scene()
    damaged = damage_depth(depth, color, only(shadow_px=4), np.random.default_rng(0))
    lost = damaged == 0
    assert lost[20:40, 50:54].all()  # the wall right of the box, 4 px
    assert not lost[20:40, 54:].any() and not lost[20:40, :50].any()
    edges = damage_depth(depth, color, only(edge_px=1), np.random.default_rng(0))
    assert (edges[20:40, 29:31] == 0).all() and (edges[20:40, 49:51] == 0).all()
    assert (edges[:15] > 0).all()


def test_dark_and_glossy_pixels_lose_their_depth() -> None:
    depth, color = scene()
    color[:10] = 10  # a dark band
    color[50:] = 255  # saturated: glossy
    damaged = damage_depth(depth, color, only(dark_below=25, dark_drop=1.0, glossy_above=250),
                           np.random.default_rng(0))
    assert (damaged[:10] == 0).all() and (damaged[50:] == 0).all()
    assert (damaged[10:50] > 0).all()
    with pytest.raises(ValueError, match="within"):
        DepthDamage(row_share=1.5)


@pytest.fixture
def labelled_set(tmp_path: Path) -> Path:
    """Two frames of the wall-and-box scene as a labelled set (the box is segment 2)."""
    folder = tmp_path / "boxes"
    for kind in ("color", "depth", "label"):
        (folder / kind).mkdir(parents=True)
    depth, color = scene()
    truth = np.where(depth == 800, 2, 1).astype(np.uint16)
    for index in range(2):
        name = f"{index:06d}.png"
        cv2.imwrite(str(folder / "color" / name), color[..., ::-1])
        cv2.imwrite(str(folder / "depth" / name), depth)
        cv2.imwrite(str(folder / "label" / name), truth)
    (folder / "camera.json").write_text(json.dumps(
        {"fx": 70.0, "fy": 70.0, "cx": 39.5, "cy": 29.5, "width": WIDTH, "height": HEIGHT,
         "depth_scale": 1000.0}))
    return folder


def test_a_damaged_source_drops_the_same_pixels_on_every_pass(labelled_set: Path) -> None:
    source = DamagedSource(open_source(labelled_set), DepthDamage(), 5)
    first = [frame.depth for _, frame in source.frames()]
    second = [frame.depth for _, frame in source.frames()]
    assert all(np.array_equal(a, b) for a, b in zip(first, second, strict=True))
    assert not np.array_equal(first[0], first[1])  # seeded per frame too
    assert "seed 5" in source.describe()


def test_eval_scores_only_the_pixels_that_keep_their_depth(labelled_set: Path,
                                                          tmp_path: Path) -> None:
    profile = tmp_path / "small.toml"
    profile.write_text(SMALL_PROFILE)
    everything = DepthDamage(row_share=1.0, min_stripe_length=1.0)  # no depth left
    settings = SegmentationEvalSettings(modes=("independent",), params=profile, peer=False,
                                        figures=0, worst=0, damage_seed=1, damage=everything)
    data = evaluate_segmentation(labelled_set, settings, tmp_path / "all", progress=False)
    assert data["damage"]["seed"] == 1 and data["damage"]["row_share"] == 1.0
    assert data["methods"]["gngdt independent"]["summary"]["truth_segments"] == 0


def test_the_cli_runs_on_damaged_frames(labelled_set: Path, tmp_path: Path) -> None:
    profile = tmp_path / "small.toml"
    profile.write_text(SMALL_PROFILE)
    out = tmp_path / "report"
    assert gngdt(["eval", "segmentation", str(labelled_set), "--out", str(out), "--no-peer",
                  "--no-progress", "--independent", "--params", str(profile),
                  "--damage-depth", "7", "--figures", "0"]) == 0
    data = json.loads((out / "segmentation.json").read_text())
    assert data["damage"]["seed"] == 7
    assert data["methods"]["gngdt independent"]["summary"]["truth_segments"] == 2
    assert "Depth damaged (seed 7)" in (out / "segmentation.md").read_text()
    plain = tmp_path / "plain"
    assert gngdt(["eval", "segmentation", str(labelled_set), "--out", str(plain), "--no-peer",
                  "--no-progress", "--independent", "--params", str(profile),
                  "--figures", "0"]) == 0
    assert json.loads((plain / "segmentation.json").read_text())["damage"] is None
