"""Synthetic scenes for the virtual Kinect: layouts of solid primitives
(:mod:`gngdt.io.synth.primitives`) with a camera path and object motions
(:mod:`gngdt.io.synth.motion`), and what a clustering of each should find.

World frame: x right, y forward (away from the default camera), z up, metres.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace

from gngdt.core.clustering import BY_COLOUR_AND_NORMAL, COL, NOR, POS
from gngdt.io.synth.motion import CameraPath, Motion, Orbit, Walk
from gngdt.io.synth.primitives import (
    Cylinder,
    Primitive,
    Rectangle,
    Sphere,
    box,
    triangular_prism,
)


@dataclass(frozen=True)
class Scene:
    """Primitives, the camera path, and what the scene should look like to a clustering."""

    name: str
    description: str
    primitives: tuple[Primitive, ...]
    #: the camera's path (an Orbit or a Walk)
    orbit: CameraPath
    #: RGB 0-255 where a ray hits nothing
    background: tuple[int, int, int]
    #: expected cluster counts per GNG-DT topology, see ``SCENE_GROUND_TRUTH`` in synth.py
    ground_truth: dict[str, object]
    #: primitives that move or vanish during the recording
    motions: tuple[Motion, ...] = ()
    #: names of primitives that are not there (rays pass through them); set by :meth:`at`
    absent: frozenset[str] = frozenset()

    def primitive(self, name: str) -> Primitive:
        """The primitive called ``name``; ``KeyError`` if there is none."""
        for candidate in self.primitives:
            if candidate.name == name:
                return candidate
        raise KeyError(f"scene {self.name!r} has no primitive {name!r}")

    def at(self, time_s: float) -> Scene:
        """The scene as it is ``time_s`` seconds after the first frame (itself when static).

        Primitives keep their places in ``primitives`` (so segment ids stay the same); a moved
        one is replaced by its translated copy, a vanished one is named in ``absent``.
        """
        if not self.motions:
            return self
        primitives = list(self.primitives)
        absent = set(self.absent)
        for motion in self.motions:
            index = next(
                i for i, candidate in enumerate(primitives) if candidate.name == motion.primitive
            )
            if motion.vanish:
                if time_s >= motion.start_s:
                    absent.add(motion.primitive)
            else:
                primitives[index] = primitives[index].translated(motion.displacement(time_s))
        return replace(self, primitives=tuple(primitives), absent=frozenset(absent))


BROWN = (140, 90, 50)
RED = (200, 35, 35)


def data2_scene() -> Scene:
    """The paper's Data2: a half red / half brown square prism and a red half cylinder on a
    brown surface (section 3.1, Figures 7b and 11).

    The square prism (0.2 x 0.2 m cross-section, 0.7 m long) lies along x; its lower half is
    brown like the surface, its upper half red. The half cylinder is a 0.1 m radius cylinder
    whose axis lies in the surface, so only its upper half shows. The camera stays within
    x = +-0.35 m of the centre, so the objects' ends and back faces are never seen.

    Seen regions, giving the paper's Figure 11 counts:
    colour: {surface + prism lower half} brown, {prism top + upper front} red, cylinder -> 3;
    normal: surface, prism top, prism front, curved cylinder -> 4;
    colour+normal: surface, prism top, prism front red, prism front brown, cylinder -> 5;
    position: everything touches the surface -> 1.
    """
    length = 0.7
    primitives: tuple[Primitive, ...] = (
        Rectangle("surface", BROWN, center=(0.0, 0.0, 0.0), half_size=(0.6, 0.5)),
        box("prism_lower", BROWN, center=(0.0, 0.15, 0.05), size=(length, 0.2, 0.1)),
        box("prism_upper", RED, center=(0.0, 0.15, 0.15), size=(length, 0.2, 0.1)),
        Cylinder(
            "half_cylinder",
            RED,
            base_center=(-length / 2, -0.2, 0.0),
            axis=(1.0, 0.0, 0.0),
            radius=0.1,
            height=length,
        ),
    )
    return Scene(
        name="data2",
        description="the paper's Data2: half red/half brown square prism and red half cylinder "
        "on a brown surface",
        primitives=primitives,
        orbit=Orbit(
            target=(0.0, 0.0, 0.08),
            distance=1.2,
            elevation_deg=48.0,
            azimuth_swing_deg=10.0,
            elevation_swing_deg=6.0,
            distance_swing=0.1,
            period_s=8.0,
        ),
        background=(0, 0, 0),
        ground_truth={POS: 1, COL: 3, NOR: 4, BY_COLOUR_AND_NORMAL.name: 5},
    )


TABLE_TOP_HEIGHT = 0.74


def _tabletop_primitives() -> tuple[Primitive, ...]:
    """The tabletop scene's floor, wall, table and four objects."""
    wood = (150, 105, 60)
    top = TABLE_TOP_HEIGHT
    # Two full-depth side panels rather than four legs: the back legs of a four-legged table
    # peek out under the top as small separate regions, which would blur the ground truth.
    sides = tuple(
        box(
            f"table_side_{side}",
            wood,
            center=(sign * 0.58, 0.3, (top - 0.04) / 2),
            size=(0.04, 0.8, top - 0.04),
        )
        for side, sign in (("left", -1.0), ("right", 1.0))
    )
    return (
        Rectangle("floor", (105, 105, 110), center=(0.0, 0.0, 0.0), half_size=(4.0, 4.0)),
        Rectangle(
            "wall",
            (225, 215, 190),
            center=(0.0, 1.5, 1.0),
            normal=(0.0, -1.0, 0.0),
            axis_u=(1.0, 0.0, 0.0),
            half_size=(4.0, 1.0),
        ),
        box("table_top", wood, center=(0.0, 0.3, top - 0.02), size=(1.2, 0.8, 0.04)),
        *sides,
        box(
            "red_box",
            (210, 40, 40),
            center=(-0.35, 0.25, top + 0.09),
            size=(0.18, 0.18, 0.18),
            yaw_deg=25.0,
        ),
        Cylinder(
            "green_cylinder",
            (40, 170, 60),
            base_center=(-0.05, 0.45, top),
            radius=0.06,
            height=0.22,
        ),
        Sphere("blue_sphere", (40, 80, 200), center=(0.15, 0.15, top + 0.08), radius=0.08),
        triangular_prism(
            "yellow_prism",
            (230, 200, 40),
            base_center=(0.4, 0.4, top),
            length=0.22,
            width=0.14,
            height=0.12,
            yaw_deg=-20.0,
        ),
    )


#: the tabletop scene's camera arc: 1.9-2.1 m from the table, 30-40 degrees above, +-20 degrees
TABLETOP_ORBIT = Orbit(
    target=(0.0, 0.3, 0.45),
    distance=2.0,
    elevation_deg=35.0,
    azimuth_swing_deg=20.0,
    elevation_swing_deg=5.0,
    distance_swing=0.1,
    period_s=12.0,
)


def tabletop_scene() -> Scene:
    """A table with four coloured objects, standing on a floor in front of a wall.

    Colour regions: floor, wall, table (top and side panels), red box, green cylinder, blue sphere,
    yellow prism -> 7. Dominant plane orientations: up (floor, table top, object tops) and the
    wall's normal, facing the camera.
    """
    return Scene(
        name="tabletop",
        description="a table with a red box, green cylinder, blue sphere and yellow prism, "
        "on a floor in front of a wall",
        primitives=_tabletop_primitives(),
        orbit=TABLETOP_ORBIT,
        background=(0, 0, 0),
        ground_truth={
            COL: 7,
            "plane_normals": {"up": (0.0, 0.0, 1.0), "wall": (0.0, -1.0, 0.0)},
        },
    )


#: when the tabletop's objects change in the moving scenes, seconds after the first frame
CHANGE_AT_S = 2.0


def tabletop_vanish_scene() -> Scene:
    """The tabletop, camera orbiting as in ``tabletop``; the red box vanishes 2 s in (frame 60
    at 30 fps, when a learner at 10,000 steps a frame has just reached 1,000 nodes), leaving the
    table top under it to be seen."""
    return Scene(
        name="tabletop_vanish",
        description="tabletop with the camera orbiting; the red box vanishes 2 s in",
        primitives=_tabletop_primitives(),
        orbit=TABLETOP_ORBIT,
        background=(0, 0, 0),
        ground_truth={},
        motions=(Motion("red_box", start_s=CHANGE_AT_S, vanish=True),),
    )


def tabletop_move_scene() -> Scene:
    """The tabletop, camera orbiting as in ``tabletop``; from 2 s to 3.5 s in the blue sphere
    slides 0.3 m away from the camera (+y, 0.2 m/s) across the table, then rests."""
    return Scene(
        name="tabletop_move",
        description="tabletop with the camera orbiting; the blue sphere slides 0.3 m across "
        "the table from 2 s to 3.5 s",
        primitives=_tabletop_primitives(),
        orbit=TABLETOP_ORBIT,
        background=(0, 0, 0),
        ground_truth={},
        motions=(
            Motion("blue_sphere", start_s=CHANGE_AT_S, end_s=CHANGE_AT_S + 1.5,
                   offset=(0.0, 0.3, 0.0)),
        ),
    )


def tabletop_walk_scene() -> Scene:
    """The tabletop plus a crate on the floor to its left and a bin to its right; the camera
    walks 3.2 m sideways past them and back (8 s period: 4 s one way), so the crate leaves the
    view on the way out and comes back into it on the way back. Nothing in the scene moves."""
    primitives = (
        *_tabletop_primitives(),
        box("crate", (70, 140, 160), center=(-1.7, 0.5, 0.25), size=(0.5, 0.5, 0.5), yaw_deg=10),
        Cylinder("bin", (150, 60, 150), base_center=(1.7, 0.4, 0.0), radius=0.25, height=0.6),
    )
    return Scene(
        name="tabletop_walk",
        description="a camera walking 3.2 m past the tabletop, a crate and a bin, and back "
        "(static scene)",
        primitives=primitives,
        orbit=Walk(
            start=(-1.6, -1.3, 1.5),
            end=(1.6, -1.3, 1.5),
            look_start=(-1.4, 0.6, 0.4),
            look_end=(1.4, 0.6, 0.4),
            period_s=8.0,
        ),
        background=(0, 0, 0),
        ground_truth={},
    )


#: scene name -> builder. Builders are cheap; scenes are immutable.
SCENE_BUILDERS: dict[str, Callable[[], Scene]] = {
    "data2": data2_scene,
    "tabletop": tabletop_scene,
    "tabletop_walk": tabletop_walk_scene,
    "tabletop_vanish": tabletop_vanish_scene,
    "tabletop_move": tabletop_move_scene,
}


def build_scene(name: str) -> Scene:
    """The scene called ``name``; ``ValueError`` naming the known scenes otherwise."""
    try:
        return SCENE_BUILDERS[name]()
    except KeyError:
        raise ValueError(
            f"scene: unknown scene {name!r}; known scenes: {', '.join(sorted(SCENE_BUILDERS))}"
        ) from None
