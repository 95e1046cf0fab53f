"""Make the README's picture of a learned topology: ``python docs/make_figures.py``.

Learns GNG-DT offline on a recording as the live learner would (frames deprojected by the capture
service's ``Deprojector``, one ``partial_fit`` per frame, the learner's parameters), then
draws, over the last frame's colour image, the learned network and its clusterings by colour and
by surface normal (``docs/topology.png``). Deterministic: same recording and seed, same picture.
"""

from __future__ import annotations

import argparse
import logging
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

REPO_ROOT = Path(__file__).resolve().parents[1]

from gngdt.core.clustering import COL, NOR, POS  # noqa: E402
from gngdt.io.frame import CameraIntrinsics  # noqa: E402

if TYPE_CHECKING:
    from matplotlib.figure import Figure

log = logging.getLogger("make_figures")

#: learning steps per frame: as `tests/process/test_pipeline.py` runs data2 (`gngdt run
#: --samples-per-frame 40000`); at the live default (10000) the 30 frames leave the normal
#: topology visibly young
SAMPLES_PER_FRAME = 40_000
#: colours in the saved PNG (a palette image keeps the file small)
PNG_COLOURS = 256
#: how much of the colour image shows through behind the network drawings (0..1)
BACKGROUND_STRENGTH = 0.35
#: the two clusterings drawn, with the topology whose edges define each and a caption
CLUSTERING_PANELS = (
    (COL, "Clusters by colour (colour topology)"),
    (NOR, "Clusters by surface orientation (normal topology)"),
)


@dataclass
class LearnedScene:
    """A trained model and the last frame it learned from.

    color: (H, W, 3) uint8 RGB image of the last frame; intrinsics: its pinhole calibration;
    model: the fitted ``GNGDT`` (node positions in that camera's frame, metres).
    """

    color: np.ndarray
    intrinsics: CameraIntrinsics
    model: Any
    frames: int
    min_cluster_size: int


def learn_scene(recording: Path, params: Path | None, samples_per_frame: int,
                seed: int) -> LearnedScene:
    """Learn every frame of ``recording`` as the live learner would (``--params`` file)."""
    from gngdt.core import GNGDT
    from gngdt.io.deproject import Deprojector
    from gngdt.io.mcap.reader import read_frames
    from gngdt.io.profiles import load_profile

    config = load_profile(params).config
    model = GNGDT(**{**config.model, "random_state": seed})
    deproject = Deprojector()
    last = None
    frames = 0
    for frame in read_frames(recording):
        positions, colors = deproject(frame.depth, frame.color, frame.intrinsics)
        if len(positions) == 0:
            log.warning("%s: frame %d has no valid depth; skipped", recording, frame.index)
            continue
        model.partial_fit(positions, colors, n_steps=samples_per_frame)
        last = frame
        frames += 1
    if last is None:
        raise ValueError(f"{recording}: no frame with valid depth to learn from")
    log.info("%s: %d frames, %d nodes, %d steps", recording, frames, model.n_nodes_,
             model.n_steps_)
    return LearnedScene(last.color, last.intrinsics, model, frames,
                        config.options.min_cluster_size)


def project(positions: np.ndarray, intrinsics: CameraIntrinsics) -> np.ndarray:
    """Pixel coordinates (N, 2) float64 (u right, v down) of camera-frame points (N, 3) metres."""
    positions = np.asarray(positions, dtype=np.float64)
    depth = np.maximum(positions[:, 2], 1e-6)
    u = intrinsics.fx * positions[:, 0] / depth + intrinsics.cx
    v = intrinsics.fy * positions[:, 1] / depth + intrinsics.cy
    return np.column_stack([u, v])


def faded(image: np.ndarray) -> np.ndarray:
    """(H, W, 3) float RGB in 0..1: the image in grey, washed towards white, as a backdrop."""
    grey = image.astype(np.float64).mean(axis=2, keepdims=True) / 255.0
    return np.repeat(1.0 - BACKGROUND_STRENGTH * (1.0 - grey), 3, axis=2)


def draw_network(axis: Any, scene: LearnedScene, edges: np.ndarray, node_colours: np.ndarray,
                 edge_colours: np.ndarray | str, title: str) -> None:
    """Nodes (coloured (N, 3|4) floats 0..1) and edges (E, 2) over the faded image."""
    from matplotlib.collections import LineCollection

    pixels = project(scene.model.positions_, scene.intrinsics)
    axis.imshow(faded(scene.color))
    segments = pixels[np.asarray(edges, dtype=np.int64).reshape(-1, 2)]
    axis.add_collection(LineCollection(segments, colors=edge_colours, linewidths=0.6, zorder=2))
    axis.scatter(pixels[:, 0], pixels[:, 1], c=node_colours, s=9, linewidths=0.3,
                 edgecolors="black", zorder=3)
    finish_panel(axis, scene, title)


def finish_panel(axis: Any, scene: LearnedScene, title: str) -> None:
    axis.set_xlim(0, scene.intrinsics.width)
    axis.set_ylim(scene.intrinsics.height, 0)
    axis.set_xticks([])
    axis.set_yticks([])
    axis.set_title(title, fontsize=9)


def make_topology_figure(scene: LearnedScene, out: Path, source: str) -> Path:
    """The 2x2 README figure: image, learned network, colour clusters, normal clusters."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from gngdt.eval.plots import cluster_colours

    model = scene.model
    aspect = scene.intrinsics.height / scene.intrinsics.width
    figure, axes = plt.subplots(2, 2, figsize=(8.0, 8.0 * aspect + 0.9))
    image_axis, network_axis, *cluster_axes = axes.ravel()

    image_axis.imshow(scene.color)
    finish_panel(image_axis, scene, f"What the camera sees (frame {scene.frames} of {source})")

    learned_colours = model.colors_.astype(np.float64) / 255.0
    draw_network(network_axis, scene, model.edges(POS), learned_colours, "0.25",
                 f"Learned network: {model.n_nodes_} nodes, learned colours")

    for axis, (prop, caption) in zip(cluster_axes, CLUSTERING_PANELS, strict=True):
        labels = np.asarray(model.clusters(prop, min_size=scene.min_cluster_size))
        edges = np.asarray(model.edges(prop), dtype=np.int64).reshape(-1, 2)
        colours = cluster_colours(labels)
        count = len(np.unique(labels[labels >= 0]))
        draw_network(axis, scene, edges, colours, colours[edges[:, 0]],
                     f"{caption}: {count} clusters")

    figure.suptitle("GNG-DT learns one network, with a separate topology per property",
                    fontsize=11)
    figure.text(0.5, 0.005, "Clusters are the connected components of one topology's edges.\n"
                f"Grey: nodes in no cluster of {scene.min_cluster_size}+ nodes (e.g. on a curved "
                "surface, whose normal keeps turning).", ha="center", va="bottom", fontsize=8)
    figure.tight_layout(rect=(0, 0.04, 1, 1), h_pad=1.5)
    save_small_png(figure, out)
    plt.close(figure)
    return out


def save_small_png(figure: Figure, out: Path) -> None:
    """Save ``figure`` as a palette PNG (a few times smaller than matplotlib's RGBA)."""
    from io import BytesIO

    from PIL import Image

    buffer = BytesIO()
    figure.savefig(buffer, format="png", dpi=100)
    buffer.seek(0)
    with Image.open(buffer) as image:
        palette = image.convert("RGB").quantize(PNG_COLOURS, method=Image.Quantize.MEDIANCUT)
    out.parent.mkdir(parents=True, exist_ok=True)
    palette.save(out, optimize=True)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--recording", type=Path, default=REPO_ROOT / "recordings" / "data2.mcap")
    parser.add_argument("--out", type=Path, default=REPO_ROOT / "docs" / "topology.png")
    parser.add_argument("--params", type=Path, metavar="FILE.toml",
                        help="learner parameters, as for `gngdt learn` (default: its defaults)")
    parser.add_argument("--samples-per-frame", type=int, default=SAMPLES_PER_FRAME,
                        help=f"learning steps per frame (default {SAMPLES_PER_FRAME})")
    parser.add_argument("--seed", type=int, default=0, help="model seed (default 0)")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    scene = learn_scene(args.recording, args.params, args.samples_per_frame, args.seed)
    out = make_topology_figure(scene, args.out, args.recording.name)
    print(f"wrote {out} ({out.stat().st_size / 1024:.0f} KB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
