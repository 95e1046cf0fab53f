"""How the logger's rerun recording is laid out: entity paths per camera and the blueprint.

Entities (docs/contracts.md "Rerun") for the default camera ``camera``: ``world/camera`` (Pinhole),
``world/camera/image/rgb`` (JPEG), ``world/camera/image/depth``, ``world/points``,
``world/gng/nodes`` (positions once, in their learned colours, with each clustering's node
colours beside them as ``gngdt.clusters.<clustering>:colors``), ``world/gng/edges/<clustering>``,
``world/objects`` and ``metrics/<name>``. Any other camera ``<cam>`` gets the same tree under
``world/<cam>/`` and ``metrics/<cam>/``. The blueprint: the images, a 3D view per clustering
(`gngdt.core.clustering.CLUSTERINGS`) plus one of the cloud and the learned colours, all starting
from the camera's viewpoint, and one plot per metric.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from gngdt.core.clustering import CLUSTERINGS, SEGMENTS
from gngdt.schemas.wire import DEFAULT_CAMERA

#: clusterings with a 3D view, in view order
CLUSTERING_VIEWS = tuple(CLUSTERINGS)
#: the clustering whose view also shows the objects
OBJECTS_VIEW = SEGMENTS.name


@dataclass(frozen=True)
class EntityPaths:
    """Entity paths of one camera: the contract's paths for the default camera, else under
    ``<cam>``."""

    camera: str

    @property
    def world(self) -> str:
        return "world" if self.camera == DEFAULT_CAMERA else f"world/{self.camera}"

    @property
    def pinhole(self) -> str:
        return f"{self.world}/camera"

    @property
    def rgb(self) -> str:
        return f"{self.pinhole}/image/rgb"

    @property
    def depth(self) -> str:
        return f"{self.pinhole}/image/depth"

    @property
    def points(self) -> str:
        return f"{self.world}/points"

    @property
    def nodes(self) -> str:
        return f"{self.world}/gng/nodes"

    @property
    def objects(self) -> str:
        return f"{self.world}/objects"

    def edges(self, clustering: str) -> str:
        return f"{self.world}/gng/edges/{clustering}"

    def metric(self, name: str) -> str:
        if self.camera == DEFAULT_CAMERA:
            return f"metrics/{name}"
        return f"metrics/{self.camera}/{name}"


#: the metric plots: title (with unit) and the metric names each shows
METRIC_PLOTS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("nodes (count)", ("nodes",)),
    # segments are many (single nodes at creases count): their objects are plotted instead
    ("clusters per clustering (count)", tuple(f"clusters/{name}" for name in CLUSTERING_VIEWS
                                              if name != OBJECTS_VIEW)),
    ("objects (count)", ("objects",)),
    ("quantization error, position (m)", ("quantization_error/pos",)),
    ("quantization error, colour (RGB 0-255)", ("quantization_error/col",)),
    ("learning speed (steps/s)", ("steps_per_second",)),
    ("latency, capture to topology (ms)", ("latency_ms",)),
    ("frames dropped (count)", ("frames_dropped",)),
    ("ghost share of the seen nodes", ("ghost_share",)),
    ("nodes forgotten (count)", ("nodes_forgotten",)),
)


@dataclass(frozen=True)
class Framing:
    """Where a camera's 3D views start. In the camera's own frame (RDF: at the origin, looking
    along +z), the topology views start from the camera itself, looking along its axis at the
    scene's median depth, so that they show the nodes as the colour image shows the scene
    (rerun's views are wider than a depth camera's field of view, so a little smaller); the
    overview starts behind and above the camera, so that the camera (frustum and image) is in
    sight with the scene beyond. With camera poses the same places are taken from the camera's
    pose when the views were framed, in the fixed frame.
    """

    depth: float = 1.5
    #: camera-to-frame pose (4, 4), row-major, as a tuple (identity: the camera's own frame)
    pose: tuple[float, ...] = tuple(np.eye(4).ravel())
    #: the world's up in the frame (`gngdt.io.outputs.up_axis`); None: the camera's up
    world_up: tuple[float, float, float] | None = None

    def _place(self, x: float, y: float, z: float) -> tuple[float, float, float]:
        pose = np.asarray(self.pose).reshape(4, 4)
        return tuple(float(v) for v in pose[:3, :3] @ (x, y, z) + pose[:3, 3])

    @property
    def target(self) -> tuple[float, float, float]:
        return self._place(0.0, 0.0, self.depth)

    @property
    def camera_eye(self) -> tuple[float, float, float]:
        return self._place(0.0, 0.0, 0.0)

    @property
    def overview_eye(self) -> tuple[float, float, float]:
        return self._place(0.0, -0.2 * self.depth, -0.15 * self.depth)

    @property
    def up(self) -> tuple[float, float, float]:
        """The views' up: the world's, else the camera's (-y in RDF) in the frame."""
        if self.world_up is not None:
            return tuple(float(v) for v in self.world_up)
        rotation = np.asarray(self.pose).reshape(4, 4)[:3, :3]
        return tuple(float(v) for v in rotation @ (0.0, -1.0, 0.0))

    @classmethod
    def of(cls, positions: np.ndarray, pose: np.ndarray | None = None,
           world_up: tuple[float, float, float] | None = None) -> Framing:
        """Framing the nodes ``positions`` (N, 3), metres, seen by a camera at ``pose``
        (camera-to-frame (4, 4); None: the nodes are in the camera's frame), the views' up
        ``world_up`` (None: the camera's)."""
        pose = np.eye(4) if pose is None else np.asarray(pose, dtype=np.float64)
        local = (np.asarray(positions, dtype=np.float64) - pose[:3, 3]) @ pose[:3, :3]
        depth = float(np.median(local[:, 2]))
        return cls(depth if depth > 0.05 else cls.depth, tuple(pose.ravel()), world_up)


def _spatial_view(name: str, origin: str, contents: list[str], framing: Framing,
                  eye: tuple[float, float, float], overrides: dict[str, Any] | None = None
                  ) -> Any:
    """A 3D view starting at ``eye``, looking at the scene, on a dark background."""
    import rerun.blueprint as rrb

    return rrb.Spatial3DView(
        name=name, origin=origin, contents=contents, overrides=overrides,
        eye_controls=rrb.EyeControls3D(position=eye, look_target=framing.target,
                                       eye_up=framing.up),
        background=rrb.Background(color=[22, 24, 28]))


def _cluster_colored_nodes(paths: EntityPaths, clustering: str) -> dict[str, Any]:
    """A view's override: its nodes take their colours from ``clustering``'s colours
    (`cluster_archetype`), logged beside the positions on the one nodes entity."""
    import rerun as rr
    from rerun.blueprint.encodings import ComponentSourceKind, VisualizerComponentMapping

    mapping = VisualizerComponentMapping(
        target="Points3D:colors", source_kind=ComponentSourceKind.SourceComponent,
        source_component=f"{cluster_archetype(clustering)}:colors")
    return {paths.nodes: [rr.Points3D.from_fields().visualizer(mappings=[mapping])]}


def _camera_row(camera: str, framing: Framing) -> Any:
    """The images beside a grid of six 3D views: objects and segments, one per clustering of
    properties, and the cloud with the nodes in their learned colours."""
    import rerun.blueprint as rrb

    paths = EntityPaths(camera)
    suffix = "" if camera == DEFAULT_CAMERA else f" ({camera})"
    eye = framing.camera_eye
    views = [_spatial_view(f"objects and {OBJECTS_VIEW}{suffix}", paths.world, [
        paths.objects, paths.nodes, paths.edges(OBJECTS_VIEW)], framing, eye,
        _cluster_colored_nodes(paths, OBJECTS_VIEW))]
    views += [_spatial_view(f"{name} clusters{suffix}", paths.world,
                            [paths.nodes, paths.edges(name)], framing, eye,
                            _cluster_colored_nodes(paths, name))
              for name in CLUSTERING_VIEWS if name != OBJECTS_VIEW]
    views.append(_spatial_view(f"cloud, learned colours and the camera{suffix}", paths.world,
                               [paths.points, paths.nodes, paths.pinhole, paths.rgb], framing,
                               framing.overview_eye))
    images = rrb.Vertical(
        rrb.Spatial2DView(name=f"rgb{suffix}", origin=paths.pinhole, contents=[paths.rgb]),
        rrb.Spatial2DView(name=f"depth{suffix}", origin=paths.pinhole, contents=[paths.depth]),
    )
    return rrb.Horizontal(images, rrb.Grid(*views, grid_columns=3), column_shares=[1, 3])


def blueprint(cameras: list[str], framings: dict[str, Framing] | None = None) -> Any:
    """Per camera a row (`_camera_row`), then one plot per metric (all cameras in each); the
    time cursor follows the newest data (a finished file opens on its last frame)."""
    import rerun.blueprint as rrb

    framings = framings or {}
    rows = [_camera_row(camera, framings.get(camera, Framing())) for camera in cameras]
    plots = [
        rrb.TimeSeriesView(name=title, origin="/",
                           contents=[EntityPaths(camera).metric(name)
                                     for camera in cameras for name in names])
        for title, names in METRIC_PLOTS
    ]
    return rrb.Blueprint(
        rrb.Vertical(*rows, rrb.Grid(*plots, grid_columns=5),
                     row_shares=[3] * len(rows) + [1.4]),
        rrb.TimePanel(timeline="frame", play_state="following", state="collapsed"),
        collapse_panels=True)


def cluster_archetype(clustering: str) -> str:
    """Name of the node colours of ``clustering`` on the nodes entity (its component is
    ``<name>:colors``); each clustering's view draws the nodes with them."""
    return f"gngdt.clusters.{clustering}"
