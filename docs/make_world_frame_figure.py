"""Make the README's picture of three real frames in one world frame:
``python docs/make_world_frame_figure.py``.

The three TUM RGB-D freiburg1_xyz frames in ``../shared/data/rgbd/tum_fr1_xyz_dvo_examples``
(with their ground-truth camera poses, ``poses/``) are read as ``gngdt record images --poses``
reads them, deprojected as the capture does, and drawn seen from above (x right, z away from the
first camera): as they come, each in its own camera frame, then placed by their poses in the
fixed frame; last, the GNG-DT network learned from the three posed frames in that frame
(``partial_fit(..., camera_pose=pose)``, the learner's parameters). Each cloud's median distance
to the others' points is printed and written on the picture. Deterministic.
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

import numpy as np

from gngdt.core.clustering import POS

REPO_ROOT = Path(__file__).resolve().parents[1]

log = logging.getLogger("make_world_frame_figure")

TUM = REPO_ROOT.parent / "shared" / "data" / "rgbd" / "tum_fr1_xyz_dvo_examples"
#: points drawn per frame (a random subset: the figure stays legible and small)
DRAWN_POINTS = 6_000
#: learning steps per frame for the network panel (the live learner's default is 10,000;
#: three frames at that rate leave a young network): enough to grow the 1,000-node budget
SAMPLES_PER_FRAME = 200_000
FRAME_COLOURS = ("tab:red", "tab:green", "tab:blue")
#: the close-up (x, z ranges in metres, first camera's axes): thin vertical objects left of
#: the desk, where a few centimetres of misplacement show
CLOSE_UP = ((-1.45, -0.85), (2.05, 2.75))


def posed_frames(folder: Path) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """(camera-frame points (N, 3) m, colours (N, 3) u8, camera-to-world pose (4, 4)) per frame,
    through the importer `gngdt record images --format redwood --poses DIR/poses` uses."""
    from gngdt.io.deproject import Deprojector
    from gngdt.io.images import count_image_frames, iter_image_frames
    from gngdt.io.pose_files import attach_poses, load_poses

    frames = attach_poses(iter_image_frames(folder, "redwood"), load_poses(folder / "poses"),
                          count_image_frames(folder, "redwood"))
    deproject = Deprojector()
    result = []
    for frame in frames:
        points, colors = deproject(frame.depth, frame.color, frame.intrinsics)
        result.append((points.astype(np.float64), colors, frame.pose.matrix))
    return result


def median_gaps(clouds: list[np.ndarray]) -> list[float]:
    """Per cloud, the median distance (m) from its points to the nearest point of the others."""
    from scipy.spatial import cKDTree

    gaps = []
    for index, cloud in enumerate(clouds):
        others = np.concatenate([c for i, c in enumerate(clouds) if i != index])
        gaps.append(float(np.median(cKDTree(others).query(cloud[::20])[0])))
    return gaps


def in_first_camera(frames: list[tuple[np.ndarray, np.ndarray, np.ndarray]]
                    ) -> tuple[np.ndarray, list[np.ndarray], list[np.ndarray]]:
    """The clouds drawn in the first camera's axes: (world -> first camera (4, 4), each cloud as
    it comes in its own camera frame, each placed by its pose; clouds (N, 3) m)."""
    first_from_world = np.linalg.inv(frames[0][2])
    as_they_come = [points for points, _, _ in frames]
    placed = [points @ (first_from_world @ pose)[:3, :3].T + (first_from_world @ pose)[:3, 3]
              for points, _, pose in frames]
    return first_from_world, as_they_come, placed


def learn_network(frames: list[tuple[np.ndarray, np.ndarray, np.ndarray]],
                  first_from_world: np.ndarray, seed: int):
    """GNG-DT learned from the posed frames with the learner's parameters: (model, its node
    positions (M, 3) m in the first camera's axes, position error (m) per frame)."""
    from gngdt.core import GNGDT
    from gngdt.io.profiles import load_profile

    model = GNGDT(**{**load_profile(None).config.model, "random_state": seed})
    for points, colors, pose in frames:
        model.partial_fit(points, colors, n_steps=SAMPLES_PER_FRAME, camera_pose=pose)
    nodes = model.positions_ @ first_from_world[:3, :3].T + first_from_world[:3, 3]
    errors = [model.quantization_error(points @ pose[:3, :3].T + pose[:3, 3])[POS]
              for points, _, pose in frames]
    return model, nodes, errors


def draw_clouds(axes, panels: tuple[tuple[str, list[np.ndarray], str], ...],
                gaps: dict[str, list[float]], rng: np.random.Generator) -> None:
    """Draw each panel's clouds in its column of ``axes``: a random subset of each on top (with
    the close-up's box), the close-up's points below."""
    from matplotlib.patches import Rectangle

    (x0, x1), (z0, z1) = CLOSE_UP
    for column, (title, clouds, key) in enumerate(panels):
        for row, close in enumerate((False, True)):
            axis = axes[row, column]
            for index, cloud in enumerate(clouds):
                if close:
                    inside = ((cloud[:, 0] > x0) & (cloud[:, 0] < x1) & (cloud[:, 2] > z0)
                              & (cloud[:, 2] < z1))
                    shown = cloud[inside]
                else:
                    shown = cloud[rng.choice(len(cloud), size=min(DRAWN_POINTS, len(cloud)),
                                             replace=False)]
                axis.scatter(shown[:, 0], shown[:, 2], s=1.5 if close else 0.3,
                             color=FRAME_COLOURS[index], alpha=0.5,
                             label=f"frame {index}: median gap {gaps[key][index] * 1000:.0f} mm")
            axis.set_title(("close-up: " if close else "") + title, fontsize=10)
            if not close:
                axis.legend(fontsize=8, markerscale=12, loc="upper left")
                axis.add_patch(Rectangle((x0, z0), x1 - x0, z1 - z0, fill=False, lw=0.8))


def draw_network(axes, model, nodes: np.ndarray, errors: list[float]) -> None:
    """Draw the network's position edges and coloured nodes in the last column of ``axes``."""
    from matplotlib.collections import LineCollection

    edges = model.edges(POS)
    for row, axis in enumerate(axes[:, 2]):
        axis.add_collection(LineCollection(nodes[edges][:, :, [0, 2]], colors="0.6",
                                           linewidths=0.4))
        axis.scatter(nodes[:, 0], nodes[:, 2], s=8 if row else 4,
                     c=np.clip(model.colors_ / 255, 0, 1))
    axes[0, 2].set_title(f"GNG-DT learned from the three, in that frame: {model.n_nodes_} "
                         "nodes\nposition error per frame "
                         + ", ".join(f"{e * 1000:.0f}" for e in errors) + " mm", fontsize=10)
    axes[1, 2].set_title("close-up: the network", fontsize=10)


def style_axes(axes) -> None:
    """Label every axis; the top row shares the placed panel's limits, the bottom row the
    close-up's."""
    (x0, x1), (z0, z1) = CLOSE_UP
    for axis in axes.flat:
        axis.set_xlabel("x (m), first camera's axes", fontsize=8)
        axis.set_ylabel("z, away from the first camera (m)", fontsize=8)
        axis.set_aspect("equal")
        axis.tick_params(labelsize=7)
        axis.grid(True, alpha=0.3)
    for axis in axes[0]:
        axis.set_xlim(axes[0, 1].get_xlim())
        axis.set_ylim(axes[0, 1].get_ylim())
    for axis in axes[1]:
        axis.set_xlim(x0, x1)
        axis.set_ylim(z0, z1)


def make_figure(folder: Path, out: Path, seed: int = 0) -> Path:
    """Draw the clouds as they come, placed by their poses, and the network learned from
    them (each with a close-up); print the median gaps; save the picture to ``out``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    frames = posed_frames(folder)
    first_from_world, as_they_come, placed = in_first_camera(frames)
    gaps = {"as they come": median_gaps(as_they_come), "placed": median_gaps(placed)}
    for name, values in gaps.items():
        print(f"{name}: median distance to the other frames "
              + ", ".join(f"{v * 1000:.1f} mm" for v in values))
    model, nodes, errors = learn_network(frames, first_from_world, seed)

    rng = np.random.default_rng(seed)
    figure, axes = plt.subplots(2, 3, figsize=(15, 10))
    draw_clouds(axes, (("each frame in its own camera frame", as_they_come, "as they come"),
                       ("placed by their poses in one frame", placed, "placed")), gaps, rng)
    draw_network(axes, model, nodes, errors)
    style_axes(axes)
    figure.suptitle("TUM RGB-D fr1_xyz, three real Kinect frames seen from above "
                    "(../shared/data/rgbd/tum_fr1_xyz_dvo_examples)", fontsize=11)
    figure.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(out, dpi=90)
    plt.close(figure)
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=Path, default=TUM, help="the TUM sample folder")
    parser.add_argument("--out", type=Path, default=REPO_ROOT / "docs" / "tum_world_frame.png")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(message)s")
    if not (args.frames / "poses").is_dir():
        log.error("%s: no TUM frames with poses (the repository's sibling ../shared)", args.frames)
        return 2
    print(f"wrote {make_figure(args.frames, args.out)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
