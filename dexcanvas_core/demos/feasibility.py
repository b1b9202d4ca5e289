"""Which (object, manipulation type) pairs a human hand can perform: the feasibility table.

The rules follow the taxonomy (``dexcanvas_core.taxonomy.manipulation``, after Feix et al. 2016)
and the object's shape, size, placement on the table and mass (``object_geometry``, whose frame
is z-up at rest). Sizes are the extents of the object *as it rests*: ``width`` is its narrowest
horizontal extent (what a hand spans from above), ``height`` its vertical extent.

The objects are the paper's (``dexcanvas_core.taxonomy``): small ones among them — spheres of
40, 30 and 20 mm, a 20 × 27 mm mini cylinder, a 10 mm rod — and a 150 × 150 × 20 mm plate.

Hand capability bounds used below (estimates for an adult hand, stated once here; finger pads
are ~15–19 mm thick, ``mano.hand_model``):

* pad-to-pad precision grasps span at most ~70 mm with two digits, ~90 mm with three or four and
  ~100 mm with five (maximum grip aperture in reach-to-grasp studies stays under ~110–120 mm;
  the pads must also wrap a little around the object); four pads need an object ≥ 30 mm wide
  to find room side by side;
* power wraps fit cylinders of ~25–110 mm; the ring grasp (thumb and index around the object)
  ~30–70 mm;
* power sphere grasps hold the ball against the palm with the pads: below ~30 mm the flexed
  pads curl past a ball that touches the palm (such a ball is pinched, not wrapped), so the
  three-finger power sphere takes 30–70 mm balls; the four-finger one needs ≥ 35 mm for the
  ring finger's pad to reach the ball beside the index and middle; the five-fingertip precision
  sphere needs ≥ 35 mm (five pads round a smaller ball have no room);
* lateral (key) pinches press the object against the radial side of the curled index finger,
  which stands ~20 mm above the table on its own thickness: the object must be ≥ 20 mm high;
* the extension type spans a plate or disc edge to edge between the thumb and the extended
  fingers: up to ~160 mm (the thumb-to-middle-finger span of an adult hand is ~180–200 mm);
* sliding presses three pads on the object's top: it needs a top ≥ 30 mm wide;
* YCB items are grasped by their graspable part: the bowl by its rim (palmar pinch, tripod,
  lateral pinch), the scissors by their loops, the drill by its handle, the pitcher and the
  bottle by their bodies;
* pinches carry ≤ 0.5 kg, lateral (key) pinches and in-hand manipulation ≤ 0.3 kg, three- to
  five-digit precision grasps ≤ 1.0 kg; power grasps anything in the catalogue;
* an object lying flat (≤ 40 mm high, ≥ 60 mm wide) cannot be pinched from above across its
  width, and the fingers cannot wrap under an object lying on the table.

Every manipulation type has at least one feasible object (checked when the table is built).
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache

from dexcanvas_core.objects.geometry import object_geometry
from dexcanvas_core.taxonomy import GROUPS, MANIPULATION_TYPES, OBJECTS, Pair, object_spec


@dataclass(frozen=True)
class Feasibility:
    """Whether a pair can be demonstrated, and why (or why not)."""

    feasible: bool
    reason: str

    def __iter__(self):  # allows ``ok, why = table[pair]``
        yield self.feasible
        yield self.reason


@dataclass(frozen=True)
class ObjectTraits:
    """Shape facts the rules use (metres, kilograms, object resting on the table)."""

    object_id: str
    kind: str
    """``box``, ``cylinder_standing``, ``cylinder_lying``, ``disc``, ``sphere`` or the YCB id."""
    width: float
    length: float
    height: float
    mass: float

    @property
    def flat(self) -> bool:
        return self.height <= 0.04 and self.width >= 0.06

    @property
    def mm(self) -> str:
        return f"{self.width * 1e3:.0f} mm"


def object_traits(object_id: str) -> ObjectTraits:
    """The :class:`ObjectTraits` of an object (a catalogue object, or one given by a mesh)."""
    spec = object_spec(object_id)
    g = object_geometry(spec.id)
    hx, hy, hz = (2 * g.aabb_half).tolist()
    if spec.shape in ("cube", "cuboid"):
        kind = "box"
    elif spec.shape == "sphere":
        kind = "sphere"
    elif spec.shape == "cylinder":
        if hx > hy + 1e-9:
            kind = "cylinder_lying"
        elif hz < 0.5 * hx:
            kind = "disc"
        else:
            kind = "cylinder_standing"
    else:
        kind = spec.id
    return ObjectTraits(spec.id, kind, min(hx, hy), max(hx, hy), hz, spec.mass_kg)


Rule = Callable[[ObjectTraits], Feasibility]


def _yes(reason: str) -> Feasibility:
    return Feasibility(True, reason)


def _no(reason: str) -> Feasibility:
    return Feasibility(False, reason)


def _mass(t: ObjectTraits, limit: float, what: str) -> Feasibility | None:
    if t.mass > limit:
        return _no(f"{t.mass:.2f} kg is too heavy for {what} (limit {limit:g} kg)")
    return None


def _pinch(
    limit_w: float, limit_m: float, what: str, min_w: float = 0.0, min_h: float = 0.0
) -> Rule:
    """Fingertip grasps from above across the object's narrowest width ``≤ limit_w`` [m] (and
    ``≥ min_w``) of an object at least ``min_h`` [m] high and at most ``limit_m`` [kg]."""

    def rule(t: ObjectTraits) -> Feasibility:
        if t.kind == "bowl":
            if what not in ("a palmar pinch", "a tripod", "a lateral pinch"):
                return _no(
                    f"the bowl's rim is pinched with a palmar pinch, tripod or lateral "
                    f"pinch, not {what}"
                )
            return _mass(t, limit_m, what) or _yes(f"{what} on the bowl's rim")
        if t.kind in ("scissor", "largeclamp", "pitcherbase", "powerdrill"):
            return _no(f"{t.object_id}: handled by its loops or handle, not by {what}")
        if t.flat:
            return _no(
                f"lies flat ({t.height * 1e3:.0f} mm high): its {t.mm} width is too wide for "
                f"{what} and its faces are not reachable from the table"
            )
        if t.width > limit_w:
            return _no(f"narrowest width {t.mm} exceeds {what}'s {limit_w * 1e3:.0f} mm span")
        if t.width < min_w:
            return _no(f"{t.mm} is too thin for {what} (at least {min_w * 1e3:.0f} mm)")
        if t.height < min_h:
            return _no(
                f"{t.height * 1e3:.0f} mm high: the curled index finger's side stands higher "
                f"above the table than the object for {what} (at least {min_h * 1e3:.0f} mm)"
            )
        return _mass(t, limit_m, what) or _yes(f"{what} across its {t.mm} width")

    return rule


def _sphere_only(lo: float, hi: float, limit_m: float, what: str) -> Rule:
    def rule(t: ObjectTraits) -> Feasibility:
        if t.kind != "sphere":
            return _no(f"{what} is a grasp of spherical objects; {t.object_id} is a {t.kind}")
        if not lo <= t.width <= hi:
            return _no(f"Ø {t.mm} is outside {what}'s {lo * 1e3:.0f}–{hi * 1e3:.0f} mm range")
        return _mass(t, limit_m, what) or _yes(f"{what} of a Ø {t.mm} sphere")

    return rule


_UPRIGHT_ROUND = ("cylinder_standing",)
_UPRIGHT = ("box", "cylinder_standing", "mayonnaisebottle", "pitcherbase", "powerdrill")


def _wrap(lo: float, hi: float, what: str, kinds: tuple[str, ...], min_h: float) -> Rule:
    """Power wraps around an upright object (the fingers cannot go under a lying one)."""

    def rule(t: ObjectTraits) -> Feasibility:
        width = 0.034 if t.kind == "powerdrill" else t.width  # the drill's handle
        if t.kind not in kinds:
            if t.kind in ("cylinder_lying",) or t.flat:
                return _no(f"lying on the table, {t.object_id} cannot be wrapped for {what}")
            return _no(f"{what} wraps upright {'/'.join(kinds)} objects; {t.object_id} is not one")
        if not lo <= width <= hi:
            return _no(
                f"{width * 1e3:.0f} mm is outside {what}'s {lo * 1e3:.0f}–{hi * 1e3:.0f} mm range"
            )
        if t.height < min_h:
            return _no(f"{t.height * 1e3:.0f} mm is too low for {what}")
        return _yes(f"{what} around its {width * 1e3:.0f} mm section")

    return rule


def _adducted_thumb(t: ObjectTraits) -> Feasibility:
    return _wrap(0.025, 0.065, "an adducted-thumb wrap", _UPRIGHT, 0.08)(t)


def _distal(t: ObjectTraits) -> Feasibility:
    if t.kind == "scissor":
        return _yes("thumb and fingers through the scissors' loops")
    return _no("the distal type needs an object with finger loops (scissors)")


def _extension(t: ObjectTraits) -> Feasibility:
    if not (t.kind in ("box", "disc") and t.flat):
        return _no("the extension type holds a flat plate or disc by its edges")
    if t.width > 0.16:
        return _no(f"{t.mm} exceeds the extension type's 160 mm edge-to-edge span")
    return _yes(f"flat object, thumb and extended fingers on opposite edges {t.mm} apart")


def _rod(max_d: float, what: str) -> Rule:
    def rule(t: ObjectTraits) -> Feasibility:
        if t.kind == "cylinder_lying" and t.width <= max_d and t.length >= 0.1:
            return _yes(f"{what} of a Ø {t.mm} rod")
        return _no(f"{what} needs a pen-like rod (Ø ≤ {max_d * 1e3:.0f} mm, ≥ 100 mm long)")

    return rule


def _parallel_extension(t: ObjectTraits) -> Feasibility:
    if t.kind != "box":
        return _no("parallel extension presses flat pads on two parallel faces; needs a box")
    if t.height < 0.03:
        return _no(f"{t.height * 1e3:.0f} mm high: the side faces are too low for the pads")
    if t.width > 0.09:
        return _no(f"{t.mm} exceeds the 90 mm span of the extended fingers and thumb")
    return _mass(t, 1.0, "parallel extension") or _yes(f"pads on two faces {t.mm} apart")


def _rolling(t: ObjectTraits) -> Feasibility:
    if t.kind == "sphere":
        return _yes("rolled on the table under the thumb and index pads")
    if t.kind == "cylinder_lying":
        return _yes("rolled about its axis on the table under the thumb and index pads")
    return _no(f"{t.object_id} does not roll (not a sphere or a lying cylinder)")


def _sliding(t: ObjectTraits) -> Feasibility:
    if t.kind in ("sphere", "cylinder_lying"):
        return _no(f"{t.object_id} rolls instead of sliding")
    if t.kind in ("mayonnaisebottle", "pitcherbase", "powerdrill") or t.height > 2.0 * t.width:
        return _no(
            f"{t.height * 1e3:.0f} mm high on a {t.mm} base: it would tip over when pushed "
            "along the table"
        )
    if t.width < 0.03:
        return _no(f"its {t.mm} top has no room for three pads pressing it (at least 30 mm)")
    return _yes("pressed on the table and slid under the thumb, index and middle pads")


def _in_hand(what: str) -> Rule:
    def rule(t: ObjectTraits) -> Feasibility:
        if t.kind not in ("box", "sphere", "cylinder_standing", "cylinder_lying"):
            return _no(f"{what} is demonstrated with small primitives; {t.object_id} is not one")
        if not 0.025 <= t.width <= 0.06:
            return _no(f"{t.mm} is outside the 25–60 mm in-hand range for {what}")
        return _mass(t, 0.3, what) or _yes(f"{what} of a {t.mm} object held at the fingertips")

    return rule


RULES: dict[str, Rule] = {
    "ring": _wrap(0.03, 0.07, "a ring grasp", _UPRIGHT_ROUND, 0.08),
    "sphere_3_finger": _sphere_only(0.03, 0.07, 2.0, "a three-finger power sphere"),
    "sphere_4_finger": _sphere_only(0.035, 0.09, 2.0, "a four-finger power sphere"),
    "large_diameter": _wrap(0.045, 0.11, "a large-diameter wrap", _UPRIGHT, 0.05),
    "distal_type": _distal,
    "extension_type": _extension,
    "adducted_thumb": _adducted_thumb,
    "writing_tripod": _rod(0.032, "a writing tripod"),
    "tripod_variation": _rod(0.032, "a chopstick grip"),
    "lateral_pinch": _pinch(0.055, 0.3, "a lateral pinch", min_h=0.02),
    "lateral_tripod": _pinch(0.055, 0.3, "a lateral tripod", min_h=0.02),
    "palmar_pinch": _pinch(0.07, 0.5, "a palmar pinch"),
    "inferior_pincer": _pinch(0.05, 0.3, "an inferior pincer"),
    "tripod": _pinch(0.09, 1.0, "a tripod"),
    "quadpod": _pinch(0.09, 1.0, "a quadpod", min_w=0.03),
    "precision_sphere": _sphere_only(0.035, 0.09, 1.0, "a precision sphere"),
    "parallel_extension": _parallel_extension,
    "rolling": _rolling,
    "sliding": _sliding,
    "finger_transfer": _in_hand("a finger transfer"),
    "rotation": _in_hand("an in-hand rotation"),
}


@lru_cache(maxsize=1)
def feasibility_table() -> dict[tuple[str, str], Feasibility]:
    """``(object id, type name) → Feasibility`` for all 29 × 21 pairs of the catalogue."""
    table = {}
    for oid in OBJECTS:
        traits = object_traits(oid)
        for name in MANIPULATION_TYPES:
            table[(oid, name)] = RULES[name](traits)
    covered = {t for (_, t), f in table.items() if f.feasible}
    missing = sorted(set(MANIPULATION_TYPES) - covered)
    if missing:  # pragma: no cover - a rule change that drops a type must fail loudly
        raise RuntimeError(f"no feasible object for manipulation types {missing}")
    return table


def feasible_pairs() -> list[Pair]:
    """Every feasible pair, in catalogue order (objects, then types)."""
    return [Pair.of(o, t) for (o, t), f in feasibility_table().items() if f.feasible]


def feasibility(pair: str | Pair) -> Feasibility:
    """The table entry of one pair (``"cube2/tripod"`` or a :class:`Pair`)."""
    p = pair if isinstance(pair, Pair) else Pair.parse(pair)
    if p.object.mesh is not None:  # a model given by the user: judged on its own shape
        return RULES[p.manipulation_type.name](object_traits(p.object.id))
    return feasibility_table()[(p.object.id, p.manipulation_type.name)]


def spread_pairs(pairs) -> list:
    """The order in which pairs are taken, spreading them over the four groups deterministically.

    Within a group: round robin over its manipulation types (catalogue order); each type walks
    its objects starting at an offset that differs per type, so types do not all pick the same
    object. Groups are then interleaved (power, intermediate, precision, in-hand, power, …).
    Returns every pair in that order; callers take the first ``n`` that work, per group quota.
    """
    by_group: dict[str, dict[str, list]] = {g: defaultdict(list) for g in GROUPS}
    for p in pairs:
        by_group[p.manipulation_type.group][p.manipulation_type.name].append(p)
    group_orders = {}
    for g, types in by_group.items():
        order = []
        lists = list(types.values())
        depth = max((len(x) for x in lists), default=0)
        for r in range(depth):
            for k, objs in enumerate(lists):
                if r < len(objs):
                    order.append(objs[(r + 3 * k) % len(objs)])
        group_orders[g] = order
    out = []
    depth = max((len(o) for o in group_orders.values()), default=0)
    for r in range(depth):
        for g in GROUPS:
            if r < len(group_orders[g]):
                out.append(group_orders[g][r])
    return out
