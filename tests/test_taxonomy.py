"""Tests of dexcanvas_core.taxonomy: manipulation types, objects, and object/type pairs."""

from __future__ import annotations

import csv
import dataclasses
import re
from importlib import resources
from pathlib import Path

import numpy as np
import pytest

from dexcanvas_core.errors import DexCanvasError, UnknownNameError, ValidationError
from dexcanvas_core.keypoints import FINGERS
from dexcanvas_core.taxonomy import (
    GROUPS,
    HEAVY_BASES,
    MANIPULATION_TYPES,
    OBJECTS,
    SIZE_LAYOUT,
    ManipulationType,
    ObjectSpec,
    Pair,
    heavy_variant,
    manipulation_type,
    object_spec,
    types_in_group,
)
from dexcanvas_core.taxonomy.objects import CATALOGUE_FILE, CSV_COLUMNS, read_catalogue_rows

# Leaves of the paper's taxonomy figure: (group, thumb, number of digits holding the object).
FIGURE_LEAVES = {
    ("power", "abducted", 2),
    ("power", "abducted", 3),
    ("power", "abducted", 4),
    ("power", "abducted", 5),
    ("power", "adducted", 5),
    ("intermediate", "abducted", 2),
    ("intermediate", "adducted", 2),
    ("intermediate", "adducted", 3),
    ("precision", "abducted", 2),
    ("precision", "abducted", 3),
    ("precision", "abducted", 4),
    ("precision", "abducted", 5),
    ("precision", "adducted", 5),
}


# ---- manipulation types ------------------------------------------------------------------------


def test_catalogue_has_21_types_keyed_by_snake_case_name():
    assert len(MANIPULATION_TYPES) == 21
    for name, t in MANIPULATION_TYPES.items():
        assert name == t.name
        assert re.fullmatch(r"[a-z][a-z0-9]*(_[a-z0-9]+)*", name)
        assert t.description.strip()


def test_group_counts():
    counts = {g: len(types_in_group(g)) for g in GROUPS}
    assert counts == {"power": 7, "intermediate": 4, "precision": 6, "in_hand": 4}
    assert sum(counts.values()) == 21
    assert [t.name for t in types_in_group("in_hand")] == [
        "rolling",
        "sliding",
        "finger_transfer",
        "rotation",
    ]


def test_grasp_leaves_match_the_paper_figure():
    leaves = {(t.group, t.thumb, t.n_fingers) for t in MANIPULATION_TYPES.values() if t.is_grasp}
    assert leaves == FIGURE_LEAVES


def test_fingers_and_thumb_are_consistent_with_group():
    for t in MANIPULATION_TYPES.values():
        assert t.fingers, t.name
        assert set(t.fingers) <= set(FINGERS)
        assert list(t.fingers) == sorted(t.fingers, key=FINGERS.index)
        assert t.n_fingers == len(t.fingers)
        if t.group == "in_hand":
            assert t.thumb is None and not t.is_grasp and t.feix_id is None
        else:
            assert t.thumb in ("abducted", "adducted")
            assert "thumb" in t.fingers
            assert t.feix_id is not None and 1 <= t.feix_id <= 33


def test_gesture_codes_and_feix_ids_are_unique():
    codes = [t.gesture_code for t in MANIPULATION_TYPES.values() if t.gesture_code is not None]
    assert len(codes) == len(set(codes)) > 0
    feix = [t.feix_id for t in MANIPULATION_TYPES.values() if t.feix_id is not None]
    assert len(feix) == len(set(feix)) == 17


@pytest.mark.parametrize(
    ("query", "expected"),
    [
        ("tripod", "tripod"),
        ("Tripod", "tripod"),
        ("  palmar pinch ", "palmar_pinch"),
        ("Palmar-Pinch", "palmar_pinch"),
        ("lateral", "lateral_pinch"),
        ("Large Diameter", "large_diameter"),
        ("Finger transfer", "finger_transfer"),
        ("in-hand rotation", "rotation"),
        ("chopsticks", "tripod_variation"),
        (1, "palmar_pinch"),
        (np.int64(18), "lateral_pinch"),
        ("01", "palmar_pinch"),
        ("9", "large_diameter"),
        ("001-Palmar-Pinch", "palmar_pinch"),
        ("018-Lateral", "lateral_pinch"),
        ("020-Rolling", "rolling"),
        ("021-Sliding", "sliding"),
        ("010-Extension-Type", "extension_type"),
    ],
)
def test_manipulation_type_lookup(query, expected):
    assert manipulation_type(query).name == expected


def test_manipulation_type_instance_passes_through():
    t = MANIPULATION_TYPES["quadpod"]
    assert manipulation_type(t) is t


def test_unknown_manipulation_type_suggests_close_matches():
    with pytest.raises(UnknownNameError, match=r"unknown manipulation type 'tripd'.*'tripod'"):
        manipulation_type("tripd")
    with pytest.raises(UnknownNameError, match="'precision_sphere'"):
        manipulation_type("Precision Sphre")
    with pytest.raises(UnknownNameError, match=r"gesture code 99.*available: 01, 09"):
        manipulation_type(99)
    with pytest.raises(UnknownNameError, match="002-Prismatic-3-Finger"):
        manipulation_type("002-Prismatic-3-Finger")
    with pytest.raises(KeyError):  # UnknownNameError is also a KeyError and a DexCanvasError
        manipulation_type("no such grasp")
    with pytest.raises(DexCanvasError):
        manipulation_type("")


def test_manipulation_type_rejects_non_names_and_inconsistent_labels():
    with pytest.raises(ValidationError, match="bool"):
        manipulation_type(True)
    with pytest.raises(ValidationError, match="NoneType"):
        manipulation_type(None)
    with pytest.raises(ValidationError, match="inconsistent"):
        manipulation_type("001-Lateral")


def test_types_in_group_accepts_spellings_and_rejects_unknown():
    assert types_in_group("In-hand") == types_in_group("in_hand")
    with pytest.raises(UnknownNameError, match="'precision'"):
        types_in_group("precison")


def test_manipulation_type_is_frozen_and_validated():
    t = MANIPULATION_TYPES["tripod"]
    with pytest.raises(dataclasses.FrozenInstanceError):
        t.name = "other"  # type: ignore[misc]
    with pytest.raises(ValidationError, match="thumb"):
        ManipulationType("x", "in_hand", "abducted", ("thumb",), "d")
    with pytest.raises(ValidationError, match="thumb"):
        ManipulationType("x", "power", None, ("thumb",), "d")
    with pytest.raises(ValidationError, match="order"):
        ManipulationType("x", "power", "abducted", ("index", "thumb"), "d")
    with pytest.raises(ValidationError, match="empty"):
        ManipulationType("x", "power", "abducted", (), "d")
    with pytest.raises(ValidationError, match="group"):
        ManipulationType("x", "grip", "abducted", ("thumb",), "d")  # type: ignore[arg-type]


# ---- objects -----------------------------------------------------------------------------------


PAPER_TABLE = Path(__file__).parent / "data" / "paper_objects.csv"
SHARED_TABLE = Path(__file__).resolve().parents[1].parent / "shared" / "objects.csv"
SIZE_COLUMNS = ("size_x_m", "size_y_m", "size_z_m", "diameter_m", "height_m")
PAPER_HEAVY = {
    "cube2H", "cuboid2H", "cuboid3H", "cylinder1H", "cylinder4H", "cylinder5H", "cylinder6H",
    "sphere1H",
}  # fmt: skip


def _package_rows() -> list[dict[str, str]]:
    text = resources.files("dexcanvas_core.taxonomy").joinpath(CATALOGUE_FILE).read_text()
    return read_catalogue_rows(text)


def _compare_with_paper(paper_csv: Path) -> None:
    """Every row of the package catalogue against the paper's table: ids in order, sizes,
    masses (exact), heavy duplicates and placements; a cell the paper leaves empty must be
    filled by an estimate that the row's provenance marks as one."""
    with paper_csv.open(newline="") as f:
        paper = list(csv.DictReader(f))
    ours = _package_rows()
    assert [r["id"] for r in ours] == [r["id"] for r in paper]
    assert list(OBJECTS) == [r["id"] for r in paper]
    for p, o in zip(paper, ours, strict=True):
        oid = p["id"]
        spec = OBJECTS[oid]
        prov = spec.provenance()
        assert (o["description"], o["shape"], o["heavy_of"]) == (
            p["description"], p["shape"], p["heavy_of"]
        ), oid  # fmt: skip
        assert prov["mass"] == prov["heavy_of"] == "paper", oid
        assert float(o["mass_kg"]) == float(p["mass_kg"]) == spec.mass_kg, oid
        assert spec.base_id == (p["heavy_of"] or None), oid
        paper_sizes = {c: p[c] for c in SIZE_COLUMNS if p[c]}
        if paper_sizes:
            assert prov["size"] == "paper", oid
            assert {c: float(o[c]) for c in SIZE_COLUMNS if o[c]} == {
                c: float(v) for c, v in paper_sizes.items()
            }, oid
        else:
            assert prov["size"].startswith("estimate, "), oid
        if p["placement"]:
            assert prov["placement"] == "paper", oid
            assert o["placement"] == spec.placement == p["placement"], oid
        else:
            assert prov["placement"].startswith("estimate, ") and spec.placement, oid


def test_catalogue_is_the_papers_table():
    """Every row against the paper's table kept in tests/data; in a workspace that has the
    shared copy beside the repository, that copy is the same table."""
    _compare_with_paper(PAPER_TABLE)
    if SHARED_TABLE.exists():
        assert SHARED_TABLE.read_bytes() == PAPER_TABLE.read_bytes()


def test_catalogue_has_the_papers_29_objects():
    # The paper's text says "30-object set"; its table, and so the catalogue, has 29 rows.
    assert len(OBJECTS) == 29
    primitives = [o for o in OBJECTS.values() if o.is_primitive and not o.heavy]
    heavy = [o for o in OBJECTS.values() if o.heavy]
    ycb = [o for o in OBJECTS.values() if o.source == "ycb"]
    assert (len(primitives), len(heavy), len(ycb)) == (14, 8, 7)
    expected = {"cube1", "cube2"} | {f"cuboid{i}" for i in (1, 2, 3)}
    expected |= {f"cylinder{i}" for i in range(1, 7)} | {f"sphere{i}" for i in (1, 2, 3)}
    assert {o.id for o in primitives} == expected
    assert {o.id for o in heavy} == PAPER_HEAVY
    assert {o.id for o in ycb} == {
        "mayonnaisebottle",
        "banana",
        "bowl",
        "largeclamp",
        "pitcherbase",
        "powerdrill",
        "scissor",
    }


def test_paper_values_spot_check():
    # A few of the paper's numbers written out, independently of the CSV files.
    assert OBJECTS["cube2"].size_m == (0.05,) and OBJECTS["cube2"].mass_kg == 0.037
    assert OBJECTS["sphere1"].size_m == (0.04,) and OBJECTS["sphere1"].mass_kg == 0.013
    assert OBJECTS["cylinder5"].size_m == (0.02, 0.027)
    assert OBJECTS["cuboid1"].size_m == (0.15, 0.15, 0.02)
    assert OBJECTS["powerdrill"].mass_kg == 0.228
    assert OBJECTS["cube2H"].mass_kg == 0.123 and OBJECTS["cylinder1H"].mass_kg == 0.554


def test_object_fields_are_consistent():
    for oid, o in OBJECTS.items():
        assert oid == o.id
        assert len(o.size_m) == len(SIZE_LAYOUT[o.shape])
        assert all(0 < v < 1 for v in o.size_m)
        assert 0 < o.mass_kg < 5
        assert o.placement
        assert (o.shape == "mesh") == (o.source == "ycb") == o.approximate
        assert len(o.bounding_box_m) == 3
        if o.is_primitive:
            assert o.ycb_id is None and o.volume_m3 > 0
            assert o.inertia_diag_kg_m2 is not None
        else:
            assert o.volume_m3 is None and o.inertia_diag_kg_m2 is None
        # Every entry says where size, mass, heavy set and placement come from.
        assert set(o.provenance()) == {"size", "mass", "heavy_of", "placement"}, oid
        for fact in ("size:", "mass:", "placement:"):
            assert fact in o.data_source, (oid, fact)


def test_heavy_variants_have_a_lighter_base_of_the_same_size():
    assert {o.base_id for o in OBJECTS.values() if o.heavy} == set(HEAVY_BASES)
    for o in OBJECTS.values():
        if not o.heavy:
            assert o.base_id is None
            continue
        base = OBJECTS[o.base_id]
        assert not base.heavy
        assert o.id == f"{base.id}H"
        assert (o.shape, o.size_m, o.source, o.placement) == (
            base.shape, base.size_m, base.source, base.placement
        )  # fmt: skip
        assert o.mass_kg > base.mass_kg
        assert heavy_variant(base) is o
    assert heavy_variant("cuboid1") is None
    assert heavy_variant("cube1") is None


def test_placements_follow_the_paper():
    # cuboid1 large face down: 15 × 15 footprint, 2 cm high; cuboid2 long edge along x.
    assert OBJECTS["cuboid1"].size_m[2] == 0.02
    assert OBJECTS["cuboid2"].size_m[0] == max(OBJECTS["cuboid2"].size_m)
    assert OBJECTS["cuboid2H"].placement == "long edge along X"
    assert OBJECTS["powerdrill"].placement == "handle along Z"
    assert OBJECTS["cylinder4"].lying and OBJECTS["cylinder4H"].lying
    assert not OBJECTS["cylinder1"].lying and not OBJECTS["cylinder5"].lying
    assert not OBJECTS["cube2"].lying  # only cylinders lie on their side


def test_inertia_of_the_primitives():
    m = OBJECTS["cube2"].mass_kg
    assert OBJECTS["cube2"].inertia_diag_kg_m2 == pytest.approx((m * 0.05**2 / 6,) * 3)
    m = OBJECTS["cuboid1"].mass_kg
    ixx = m * (0.15**2 + 0.02**2) / 12
    assert OBJECTS["cuboid1"].inertia_diag_kg_m2 == pytest.approx((ixx, ixx, m * 0.045 / 12))
    m = OBJECTS["sphere1"].mass_kg
    assert OBJECTS["sphere1"].inertia_diag_kg_m2 == pytest.approx((0.4 * m * 0.02**2,) * 3)
    # a lying cylinder's axis is the object frame's x, a standing one's z
    m = OBJECTS["cylinder4"].mass_kg
    axial, radial = 0.5 * m * 0.005**2, m * (3 * 0.005**2 + 0.15**2) / 12
    assert OBJECTS["cylinder4"].inertia_diag_kg_m2 == pytest.approx((axial, radial, radial))
    m = OBJECTS["cylinder1H"].mass_kg
    axial, radial = 0.5 * m * 0.035**2, m * (3 * 0.035**2 + 0.15**2) / 12
    assert OBJECTS["cylinder1H"].inertia_diag_kg_m2 == pytest.approx((radial, radial, axial))


def test_catalogue_rows_are_validated():
    header = ",".join(CSV_COLUMNS)
    with pytest.raises(ValidationError, match="missing columns"):
        read_catalogue_rows("id,shape\ncube2,cube\n")
    rows = read_catalogue_rows(f"# comment\n{header}\n" + "x,d,cube,0.05,0.05,0.05,,,0.1,,,p\n")
    assert rows[0]["id"] == "x" and rows[0]["mass_kg"] == "0.1"


@pytest.mark.parametrize(
    ("query", "expected"),
    [
        ("cube2", "cube2"),
        ("CUBE2", "cube2"),
        (" Cube 2 ", "cube2"),
        ("cube2H", "cube2H"),
        ("cube2h", "cube2H"),
        ("Cube2H", "cube2H"),
        ("cube2_heavy", "cube2H"),
        ("sphere1 heavy", "sphere1H"),
        ("CYLINDER4H", "cylinder4H"),
        ("mayonnaise bottle", "mayonnaisebottle"),
        ("Mayonnaise_Bottle", "mayonnaisebottle"),
        ("Large Clamp", "largeclamp"),
        ("scissors", "scissor"),
        ("011_banana", "banana"),
        ("power_drill", "powerdrill"),
        ("pitcher", "pitcherbase"),
    ],
)
def test_object_lookup(query, expected):
    assert object_spec(query).id == expected


def test_unknown_object_suggests_close_matches():
    with pytest.raises(UnknownNameError, match=r"unknown object 'cub2'.*'cube2'"):
        object_spec("cub2")
    with pytest.raises(UnknownNameError, match="'sphere3'"):
        object_spec("spher3")
    with pytest.raises(UnknownNameError, match="'cylinder1H'"):
        object_spec("cylinder1HH")
    with pytest.raises(UnknownNameError):
        object_spec("cube1H")  # the paper has no heavy large cube
    with pytest.raises(ValidationError, match="int"):
        object_spec(2)  # type: ignore[arg-type]
    spec = OBJECTS["bowl"]
    assert object_spec(spec) is spec


def test_object_spec_is_frozen_and_validated():
    with pytest.raises(dataclasses.FrozenInstanceError):
        OBJECTS["cube1"].mass_kg = 1.0  # type: ignore[misc]
    ok = {"placement": "table", "data_source": "test"}
    with pytest.raises(ValidationError, match=r"cylinder size is \(diameter, height\)"):
        ObjectSpec("c", "C", "cylinder", (0.05,), 0.1, **ok)
    with pytest.raises(ValidationError, match="mass"):
        ObjectSpec("c", "C", "cube", (0.05,), -1.0, **ok)
    with pytest.raises(ValidationError, match="base_id"):
        ObjectSpec("c", "C", "cube", (0.05,), 0.1, heavy=True, **ok)
    with pytest.raises(ValidationError, match="mesh"):
        ObjectSpec("c", "C", "cube", (0.05,), 0.1, source="ycb", **ok)
    with pytest.raises(ValidationError, match="primitive"):
        ObjectSpec("c", "C", "mesh", (0.05, 0.05, 0.05), 0.1, **ok)
    for bad in ("", "cube/2", " cube2", "cube 2"):
        with pytest.raises(ValidationError, match="id"):
            ObjectSpec(bad, "C", "cube", (0.05,), 0.1, **ok)
    spec = ObjectSpec(
        id="Cube9H", name="C", shape="cube", size_m=(0.05,), mass_kg=0.1, placement="face down",
        data_source="test",
    )  # fmt: skip
    assert spec.id == "Cube9H"


def test_bounding_box_follows_the_size_layout():
    assert OBJECTS["cube2"].bounding_box_m == (0.05,) * 3
    assert OBJECTS["cylinder3"].bounding_box_m == (0.03, 0.03, 0.10)
    assert OBJECTS["sphere1"].bounding_box_m == (0.04,) * 3
    assert OBJECTS["bowl"].bounding_box_m == OBJECTS["bowl"].size_m
    assert OBJECTS["bowl"].volume_m3 is None


# ---- pairs -------------------------------------------------------------------------------------


def test_pair_parse_and_str_round_trip():
    pair = Pair.parse("cube2/tripod")
    assert pair.object is OBJECTS["cube2"]
    assert pair.manipulation_type is MANIPULATION_TYPES["tripod"]
    assert str(pair) == "cube2/tripod"
    assert Pair.of("cube2", "tripod") == pair
    for obj in OBJECTS:
        for kind in MANIPULATION_TYPES:
            text = f"{obj}/{kind}"
            assert str(Pair.parse(text)) == text


def test_pair_parse_normalises_spellings():
    assert str(Pair.parse(" Cube2H / Lateral ")) == "cube2H/lateral_pinch"
    assert str(Pair.parse("cube2h/tripod")) == "cube2H/tripod"
    assert Pair.parse("CUBE2H/tripod") == Pair.parse("cube2H/tripod")
    assert str(Pair.parse("banana/1")) == "banana/palmar_pinch"
    assert str(Pair.of(OBJECTS["bowl"], 9)) == "bowl/large_diameter"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("cube2tripod", "has no '/'"),
        ("cube2/tripod/x", "has 2 '/' separators"),
        ("a/b/c/d", "has 3 '/' separators"),
        ("/tripod", "the object part is empty"),
        ("cube2/", "the manipulation type part is empty"),
        ("  /  ", "the object part is empty"),
        ("", "has no '/'"),
    ],
)
def test_pair_parse_rejects_malformed_strings(text, message):
    with pytest.raises(ValidationError, match=re.escape(message)) as info:
        Pair.parse(text)
    assert "cube2/tripod" in str(info.value)  # the message shows the expected form


def test_pair_parse_reports_unknown_names():
    with pytest.raises(UnknownNameError, match=r"unknown object 'cub2'.*'cube2'"):
        Pair.parse("cub2/tripod")
    with pytest.raises(UnknownNameError, match=r"'tripd'.*'tripod'"):
        Pair.parse("cube2/tripd")
    with pytest.raises(ValidationError, match="string"):
        Pair.parse(None)  # type: ignore[arg-type]


def test_pair_requires_specs_and_is_hashable():
    with pytest.raises(ValidationError, match=r"Pair\.of"):
        Pair("cube2", "tripod")  # type: ignore[arg-type]
    pairs = {Pair.parse("cube2/tripod"), Pair.of("Cube 2", "Tripod")}
    assert len(pairs) == 1
