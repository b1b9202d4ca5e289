"""The YCB-style items as compositions of primitives: the stand-ins used when an item's model
is not given (``--objects-dir``); outputs that use one say ``approximate_object``.

Each builder returns ``(primitives, description)`` in the object frame (z up as the item rests),
dimensions in metres; masses always come from the catalogue.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from dexcanvas_core.objects.primitives import Y90, Primitive
from dexcanvas_core.rotations import aa_to_matrix, matrix_to_aa

# -- YCB-style compositions --------------------------------------------------------------------
# Each returns (primitives, description). Dimensions in metres. They approximate the items'
# shapes at the level a grasp needs (graspable widths, heights, loops, handles); the catalogue
# (``dexcanvas_core.taxonomy.objects``) documents where its bounding boxes come from.


def _mayonnaise() -> tuple[list[Primitive], str]:
    body_h, cap_h = 0.160, 0.034
    half_w, r = 0.0195, 0.031  # stadium cross-section 101 × 62 mm
    prims = [
        Primitive("box", (half_w, r, body_h / 2), (0, 0, body_h / 2), name="body"),
        Primitive("cylinder", (r, body_h / 2), (-half_w, 0, body_h / 2), name="body_side_a"),
        Primitive("cylinder", (r, body_h / 2), (half_w, 0, body_h / 2), name="body_side_b"),
        Primitive("cylinder", (0.018, cap_h / 2), (0, 0, body_h + cap_h / 2), name="cap"),
    ]
    return prims, (
        "squeeze bottle standing on its base: a stadium-section body 101 × 62 × 160 mm (a box "
        "between two cylinders of radius 31 mm) and a cap of Ø 36 × 34 mm; total 101 × 62 × "
        "194 mm, the catalogue's estimated box (the DexRobot collision mesh's)"
    )


def _banana() -> tuple[list[Primitive], str]:
    r = 0.018
    mid_h = 0.045  # half length of the middle segment's cylinder
    end_h = 0.025  # half length of each end segment's cylinder
    tilt = math.radians(28)
    prims = [Primitive("capsule", (r, mid_h), (0, 0, 0), Y90, name="middle")]
    for side in (-1.0, 1.0):
        # end segments continue from the middle segment's ends, bending towards +y
        cx = side * (mid_h + end_h * math.cos(tilt))
        cy = end_h * math.sin(tilt)
        # rotation: z → (side·cos(tilt), sin(tilt), 0), a rotation about z after the Y90 turn
        ang = side * tilt
        Rz = aa_to_matrix(np.array([0.0, 0.0, ang]))
        R = Rz @ aa_to_matrix(np.array(Y90))
        prims.append(
            Primitive("capsule", (r, end_h), (cx, cy, 0.0), tuple(matrix_to_aa(R)), name="end")
        )
    return prims, (
        "banana lying on its side: three capsules of radius 18 mm (a middle segment of 90 mm and "
        "two 50 mm end segments bent 28° towards +y); about 215 × 70 × 36 mm. The catalogue's "
        "box (95 × 69 × 220 mm) comes from a collision mesh with marker mounts; the banana "
        "itself is ~36 mm thick (YCB 011_banana)"
    )


def _bowl() -> tuple[list[Primitive], str]:
    n = 16
    r_top, r_bot, h, wall = 0.0845, 0.042, 0.071, 0.005
    slant = math.atan2(r_top - r_bot, h)
    length = math.hypot(r_top - r_bot, h)
    width = 2 * r_top * math.sin(math.pi / n) + 0.004
    prims = [Primitive("cylinder", (r_bot + 0.004, wall / 2), (0, 0, wall / 2), name="bottom")]
    for k in range(n):
        phi = 2 * math.pi * k / n
        # box frame: z along the slanted wall, x radial (wall thickness), y tangential
        Rz = aa_to_matrix(np.array([0.0, 0.0, phi]))
        Ry = aa_to_matrix(np.array([0.0, slant, 0.0]))
        R = Rz @ Ry
        rm = 0.5 * (r_top + r_bot) - 0.5 * wall * math.cos(slant)
        prims.append(
            Primitive(
                "box",
                (wall / 2, width / 2, length / 2),
                (rm * math.cos(phi), rm * math.sin(phi), h / 2),
                tuple(matrix_to_aa(R)),
                name="wall",
            )
        )
    return prims, (
        "bowl standing upright: a 5 mm wall of 16 slanted boxes from Ø 84 mm at the base to "
        "Ø 169 mm at the rim, 71 mm high, on a 5 mm base disc (YCB 024_bowl proportions, the "
        "catalogue's estimated box, the DexRobot collision mesh's)"
    )


def _clamp() -> tuple[list[Primitive], str]:
    t = 0.013  # half thickness of the flat-lying clamp
    prims = [Primitive("box", (0.035, 0.022, t), (0.065, 0.0, 0.0), name="jaws")]
    for side in (-1.0, 1.0):
        ang = side * math.radians(10)
        R = aa_to_matrix(np.array([0.0, 0.0, ang])) @ aa_to_matrix(np.array(Y90))
        prims.append(
            Primitive(
                "capsule",
                (t, 0.052),
                (-0.022, side * 0.024, 0.0),
                tuple(matrix_to_aa(R)),
                name="handle",
            )
        )
    return prims, (
        "spring clamp lying flat: a jaw block 70 × 44 × 26 mm and two handle capsules (radius "
        "13 mm, 130 mm long) spreading at ±10°; about 185 × 85 × 26 mm (YCB 051_large_clamp "
        "proportions; the catalogue's 134 × 53 × 185 mm box is a collision mesh's)"
    )


def _pitcher() -> tuple[list[Primitive], str]:
    R_body, H = 0.054, 0.235
    prims = [
        Primitive("cylinder", (R_body, H / 2), (0, 0, H / 2), name="body"),
        Primitive("capsule", (0.011, 0.055), (R_body + 0.032, 0, 0.14), name="handle"),
        Primitive("capsule", (0.010, 0.016), (R_body + 0.014, 0, 0.196), Y90, name="handle_top"),
        Primitive("capsule", (0.010, 0.016), (R_body + 0.014, 0, 0.084), Y90, name="handle_bottom"),
    ]
    return prims, (
        "pitcher standing upright: a Ø 108 × 235 mm body cylinder and a handle on its far "
        "side (+x; a vertical capsule of radius 11 mm, 32 mm outside the body, joined by two "
        "short capsules); YCB 019_pitcher_base proportions"
    )


def _drill() -> tuple[list[Primitive], str]:
    batt_h = 0.048
    handle_len = 0.095
    tilt = math.radians(12)
    Rh = aa_to_matrix(np.array([0.0, -tilt, 0.0]))
    hc = np.array([0.0, 0.0, batt_h + handle_len / 2])
    prims = [
        Primitive("box", (0.058, 0.0335, batt_h / 2), (0.0, 0, batt_h / 2), name="battery"),
        Primitive(
            "box",
            (0.017, 0.0165, handle_len / 2 + 0.01),
            tuple(hc),
            tuple(matrix_to_aa(Rh)),
            name="handle",
        ),
        Primitive("cylinder", (0.031, 0.075), (0.035, 0, 0.166), Y90, name="body"),
        Primitive("cylinder", (0.016, 0.015), (0.125, 0, 0.166), Y90, name="chuck"),
    ]
    return prims, (
        "cordless drill standing on its battery: a battery block 116 × 67 × 48 mm, a handle "
        "34 × 33 mm in section tilted 12°, a Ø 62 × 150 mm motor body and a Ø 32 × 30 mm chuck "
        "on top, handle along z; about 190 × 67 × 197 mm (the catalogue's estimated box, the "
        "DexRobot collision mesh's; YCB 035_power_drill)"
    )


def _scissors() -> tuple[list[Primitive], str]:
    r = 0.007  # ring tube radius: 14 mm thick, the catalogue's thickness
    prims: list[Primitive] = [
        Primitive("box", (0.055, 0.009, 0.003), (0.062, 0.0, 0.0), name="blades"),
    ]

    def ring(cx: float, cy: float, ax: float, ay: float, n: int, name: str) -> None:
        # a closed loop of n capsules along an ellipse with semi-axes (ax, ay) (tube centre line)
        pts = [(cx + ax * math.cos(2 * math.pi * k / n), cy + ay * math.sin(2 * math.pi * k / n))
               for k in range(n)]  # fmt: skip
        for k in range(n):
            (x0, y0), (x1, y1) = pts[k], pts[(k + 1) % n]
            dx, dy = x1 - x0, y1 - y0
            L = math.hypot(dx, dy)
            ang = math.atan2(dy, dx)
            R = aa_to_matrix(np.array([0.0, 0.0, ang])) @ aa_to_matrix(np.array(Y90))
            prims.append(
                Primitive(
                    "capsule",
                    (r, L / 2),
                    ((x0 + x1) / 2, (y0 + y1) / 2, 0.0),
                    tuple(matrix_to_aa(R)),
                    name=name,
                )
            )

    ring(-0.045, 0.024, 0.021, 0.018, 10, "thumb_loop")  # hole ≈ 28 × 22 mm
    ring(-0.050, -0.030, 0.030, 0.019, 12, "finger_loop")  # hole ≈ 46 × 24 mm
    for y in (0.012, -0.012):
        prims.append(Primitive("capsule", (0.005, 0.012), (-0.006, y, 0.0), Y90, name="shank"))
    return prims, (
        "scissors lying flat: blades 110 × 18 × 6 mm, a thumb loop (hole ≈ 28 × 22 mm) and a "
        "finger loop for two fingers (hole ≈ 46 × 24 mm) made of capsules of radius 7 mm "
        "(14 mm thick, the catalogue's thickness), joined to the pivot by two shank capsules; "
        "about 190 × 94 × 14 mm (YCB 037_scissors)"
    )


YCB_BUILDERS: dict[str, Callable[[], tuple[list[Primitive], str]]] = {
    "mayonnaisebottle": _mayonnaise,
    "banana": _banana,
    "bowl": _bowl,
    "largeclamp": _clamp,
    "pitcherbase": _pitcher,
    "powerdrill": _drill,
    "scissor": _scissors,
}
