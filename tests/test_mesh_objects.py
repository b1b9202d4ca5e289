"""Objects given as meshes: loading and its errors, convex parts, the signed-distance grid, the
disk cache, manifests and objects directories, physics with a concave mesh, and a mesh cube
against the primitive cube through retargeting and re-simulation."""

from __future__ import annotations

import json

import mujoco
import numpy as np
import pytest
import trimesh

from dexcanvas_core.demos import generate_demo
from dexcanvas_core.errors import UnknownNameError, ValidationError
from dexcanvas_core.objects.geometry import mesh_object_geometry, object_geometry, object_record
from dexcanvas_core.objects.manifest import read_manifest
from dexcanvas_core.objects.mesh import convex_parts, load_object_mesh, mesh_collision
from dexcanvas_core.objects.sdf import SdfGrid
from dexcanvas_core.sim.scene import OBJECT_BODY, add_object, add_table
from dexcanvas_core.taxonomy import (
    OBJECTS,
    ObjectSpec,
    clear_objects,
    object_spec,
    use_objects,
)

CUBE_EDGE = 0.05


@pytest.fixture(autouse=True)
def _isolated(tmp_path_factory, monkeypatch):
    """A fresh mesh cache per test module run, and no objects in use after each test."""
    monkeypatch.setenv("DEXCANVAS_CACHE_DIR", str(tmp_path_factory.getbasetemp() / "cache"))
    clear_objects()
    yield
    clear_objects()


@pytest.fixture(scope="module")
def meshes(tmp_path_factory) -> dict:
    d = tmp_path_factory.mktemp("meshes")
    out = {}
    trimesh.creation.box((CUBE_EDGE,) * 3).export(d / "cube5.obj")
    out["cube"] = d / "cube5.obj"
    # a bowl: Ø 16 cm, 6 cm high, 5 mm wall, revolved (non-convex)
    prof = np.array([[0, 0], [0.05, 0], [0.08, 0.06], [0.075, 0.06], [0.046, 0.005], [0, 0.005]])
    trimesh.creation.revolve(prof, sections=20).export(d / "bowl.stl")
    out["bowl"] = d / "bowl.stl"
    # a hexagonal bar 4 × 9 cm written in millimetres
    trimesh.creation.cylinder(radius=20, height=90, sections=6).export(d / "hexbar_mm.ply")
    out["hexbar_mm"] = d / "hexbar_mm.ply"
    trimesh.Trimesh([[0, 0, 0], [0.05, 0, 0], [0, 0.05, 0]], [[0, 1, 2]]).export(d / "open.obj")
    out["open"] = d / "open.obj"
    (d / "garbage.obj").write_text("v 1 2\nf 1 2 3 9\n")
    out["garbage"] = d / "garbage.obj"
    out["dir"] = d
    return out


def _box_sdf(p: np.ndarray, half: float) -> np.ndarray:
    q = np.abs(p) - half
    return np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)


# -- loading and checks ---------------------------------------------------------------------------


def test_cube_mesh_loads_convex_with_its_volume(meshes):
    m = load_object_mesh(meshes["cube"])
    assert m.convex
    assert m.volume_m3 == pytest.approx(CUBE_EDGE**3, rel=1e-9)
    np.testing.assert_allclose(m.extent_m, CUBE_EDGE, atol=1e-12)


def test_millimetre_mesh_needs_its_scale(meshes):
    with pytest.raises(ValidationError, match=r"spans 90 m .*scale = 0\.001"):
        load_object_mesh(meshes["hexbar_mm"])
    m = load_object_mesh(meshes["hexbar_mm"], scale=0.001)
    assert m.extent_m.max() == pytest.approx(0.09, rel=1e-6)


@pytest.mark.parametrize(
    ("key", "pattern"),
    [
        ("open", r"not a closed surface \(3 open edges\)"),
        ("garbage", r"cannot be read|holds no triangles"),
    ],
)
def test_unusable_meshes_are_refused_naming_the_file(meshes, key, pattern):
    with pytest.raises(ValidationError, match=pattern) as e:
        load_object_mesh(meshes[key])
    assert str(meshes[key]) in str(e.value)


def test_missing_and_unknown_mesh_files(meshes, tmp_path):
    with pytest.raises(ValidationError, match="no such file"):
        load_object_mesh(tmp_path / "none.obj")
    (tmp_path / "x.dae").write_text("")
    with pytest.raises(ValidationError, match=r"unknown mesh type '\.dae'"):
        load_object_mesh(tmp_path / "x.dae")


# -- convex parts and the signed distance ---------------------------------------------------------


def test_sdf_grid_of_a_cube_matches_the_exact_box_distance(meshes):
    col = mesh_collision(load_object_mesh(meshes["cube"]))
    assert len(col.parts) == 1
    rng = np.random.default_rng(0)
    p = rng.uniform(-0.05, 0.05, (5000, 3))
    d, g = col.sdf.sdf_and_normal(p)
    exact = _box_sdf(p, CUBE_EDGE / 2)
    # exact where the cell's nearest triangles hold the point's own (all but a few in 10⁴,
    # which are then off by micrometres), inside the grid and beyond it
    assert (np.abs(d - exact) < 1e-9).mean() > 0.999
    np.testing.assert_allclose(d, exact, atol=2e-5)
    np.testing.assert_allclose(np.linalg.norm(g, axis=1), 1.0, atol=1e-9)
    far = np.array([[0.3, -0.2, 0.1], [0.0, 0.0, -0.5]])
    np.testing.assert_allclose(col.sdf.sdf_and_normal(far)[0], _box_sdf(far, 0.025), atol=1e-9)
    # the normal is the distance's gradient: the face normal on a face, diagonal at a corner
    p0 = np.array([[0.031, 0.002, -0.003], [0.0, 0.0, -0.027], [0.03, 0.03, 0.03]])
    d0, g0 = col.sdf.sdf_and_normal(p0)
    np.testing.assert_allclose(d0, [0.006, 0.002, 0.005 * np.sqrt(3)], atol=1e-9)
    np.testing.assert_allclose(g0, [[1, 0, 0], [0, 0, -1], [3**-0.5] * 3], atol=1e-9)


def test_interpolated_grid_without_triangles_is_close(meshes):
    """The grid alone (trilinear interpolation) stays within a cell's size of the distance."""
    col = mesh_collision(load_object_mesh(meshes["cube"]))
    grid = SdfGrid(col.sdf.origin, col.sdf.spacing, col.sdf.values)
    rng = np.random.default_rng(2)
    p = rng.uniform(-0.05, 0.05, (2000, 3))
    exact = _box_sdf(p, CUBE_EDGE / 2)
    assert np.abs(grid.sdf_and_normal(p)[0] - exact).max() < grid.spacing


def test_sdf_gradient_matches_finite_differences():
    """The interpolant's analytic gradient against central differences (away from cell faces
    where the trilinear interpolant's gradient jumps)."""
    rng = np.random.default_rng(1)
    grid = SdfGrid(np.zeros(3), 0.01, rng.normal(size=(6, 7, 5)))
    p = (rng.integers(0, 4, (50, 3)) + rng.uniform(0.2, 0.8, (50, 3))) * 0.01
    _, g = grid.sdf_and_normal(p)
    h = 1e-6
    fd = np.stack(
        [
            (grid.sdf_and_normal(p + h * e)[0] - grid.sdf_and_normal(p - h * e)[0]) / (2 * h)
            for e in np.eye(3)
        ],
        axis=1,
    )
    np.testing.assert_allclose(g, fd / np.linalg.norm(fd, axis=1, keepdims=True), atol=1e-6)


def test_bowl_is_decomposed_cached_and_hollow(meshes):
    mesh = load_object_mesh(meshes["bowl"])
    assert not mesh.convex
    first = mesh_collision(mesh)
    assert not first.cached and len(first.parts) > 4
    again = mesh_collision(load_object_mesh(meshes["bowl"]))
    assert again.cached  # read from disk, not decomposed again
    np.testing.assert_array_equal(again.sdf.values, first.sdf.values)
    # inside the bowl's hollow (above the 5 mm bottom, inside the wall) is outside the object
    d = first.sdf.sdf_and_normal(np.array([[0.0, 0.0, 0.03], [0.0, 0.0, 0.0025]]))[0]
    assert d[0] > 0.01  # open space in the bowl
    assert d[1] < 0.0  # the bottom is solid
    # the parts together hold about the bowl's volume (coacd's hulls bulge a little)
    vol = sum(p.volume_m3 for p in first.parts)
    assert mesh.volume_m3 <= vol < 1.6 * mesh.volume_m3


def test_concave_bowl_holds_a_ball_in_simulation(meshes):
    """A 1 cm ball dropped into the bowl stays inside it, resting on its bottom."""
    geom = mesh_object_geometry("bowl", load_object_mesh(meshes["bowl"]), 0.042)
    spec = mujoco.MjSpec()
    spec.option.timestep = 0.002
    add_table(spec)
    add_object(spec, geom, mocap=False).pos = [0.0, 0.0, geom.rest_z + 1e-3]
    ball = spec.worldbody.add_body(name="ball", pos=[0.01, 0.0, 0.04])
    ball.add_freejoint()
    ball.add_geom(type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[0.01, 0, 0]).mass = 0.01
    model = spec.compile()
    data = mujoco.MjData(model)
    assert model.body_mass[model.body(OBJECT_BODY).id] == pytest.approx(0.042)
    for _ in range(1500):
        mujoco.mj_step(model, data)
    p = data.body("ball").xpos
    bowl = data.body(OBJECT_BODY).xpos
    assert np.hypot(p[0] - bowl[0], p[1] - bowl[1]) < 0.06  # within the rim's 8 cm radius
    assert p[2] == pytest.approx(0.005 + 0.01, abs=2e-3)  # on the 5 mm bottom
    assert np.linalg.norm(data.qvel[6:9]) < 0.01  # settled (it may still roll slowly)


def test_mesh_geometry_scales_with_its_grid(meshes):
    geom = mesh_object_geometry("c", load_object_mesh(meshes["cube"]), 0.037)
    big = geom.scaled(1.2)
    p = np.array([[0.04, 0.0, 0.0]])
    assert big.signed_distance(p)[0] == pytest.approx(0.04 - 0.03, abs=3e-4)
    assert big.rest_z == pytest.approx(0.03)
    assert big.lowest_z(np.eye(3), np.zeros(3)) == pytest.approx(-0.03)


def test_explicit_inertia_and_friction_reach_the_mujoco_body(meshes):
    spec = ObjectSpec.from_mesh(
        meshes["cube"], 0.05, id="block", friction=0.7, inertia_diag=(2e-5, 3e-5, 4e-5)
    )
    geom = object_geometry(spec)
    mj = mujoco.MjSpec()
    add_object(mj, geom, mocap=False)
    model = mj.compile()
    b = model.body(OBJECT_BODY).id
    assert model.body_mass[b] == pytest.approx(0.05)
    np.testing.assert_allclose(sorted(model.body_inertia[b]), [2e-5, 3e-5, 4e-5], rtol=1e-9)
    assert model.geom_friction[model.body_geomadr[b], 0] == pytest.approx(0.7)


def test_uniform_density_inertia_of_a_mesh_cube(meshes):
    geom = object_geometry(ObjectSpec.from_mesh(meshes["cube"], 0.06))
    mj = mujoco.MjSpec()
    add_object(mj, geom, mocap=False)
    model = mj.compile()
    i_cube = 0.06 * CUBE_EDGE**2 / 6.0  # m a² / 6
    np.testing.assert_allclose(model.body_inertia[model.body(OBJECT_BODY).id], i_cube, rtol=1e-6)


# -- manifests, objects directories, lookups ------------------------------------------------------


def _write_manifest(path, text: str):
    path.write_text(text)
    return path


def test_manifest_adds_objects_and_overrides_catalogue_shapes(meshes, tmp_path):
    m = _write_manifest(
        tmp_path / "objects.toml",
        f"""
[widget]
mesh = "{meshes["hexbar_mm"]}"
mass_kg = 0.09
scale = 0.001
friction = 0.9

[objects_are_case_free]
mesh = "{meshes["cube"]}"
mass_kg = 0.02

[Cube2]
mesh = "{meshes["cube"]}"
mass_kg = 0.037
""",
    )
    assert object_spec("cube2").mesh is None
    with pytest.raises(UnknownNameError, match="--objects MANIFEST"):
        object_spec("widget")
    used = use_objects(m)
    assert set(used) == {"widget", "objects_are_case_free", "cube2"}
    w = object_spec("Widget")
    assert w.source == "custom" and w.friction == 0.9 and w.mesh_scale == 0.001
    np.testing.assert_allclose(sorted(w.size_m), [0.0346, 0.04, 0.09], atol=1e-3)
    cube = object_spec("cube2")
    assert cube.mesh == str(meshes["cube"]) and cube.mass_kg == 0.037
    assert object_geometry("cube2").is_mesh
    rec = object_record("cube2")
    assert rec["shape_source"] == "mesh" and len(rec["mesh_sha256"]) == 64
    clear_objects()
    assert object_spec("cube2").mesh is None
    assert not object_geometry("cube2").is_mesh


@pytest.mark.parametrize(
    ("entry", "pattern"),
    [
        ('mesh = "{cube}"\nmas_kg = 0.1', r"unknown keys \['mas_kg'\]"),
        ('mesh = "{cube}"', "mass_kg is missing"),
        ('mesh = "{cube}"\nmass_kg = 37', r"density of .* kg/m³"),
        ('mesh = "{cube}"\nmass_kg = 0.1\nfriction = -1', "friction must be"),
        ('mesh = "{cube}"\nmass_kg = 0.1\ninertia_diag = [1, 1, 5]', "triangle inequality"),
        ('mesh = "{open}"\nmass_kg = 0.1', "not a closed surface"),
        ('mesh = "{hexbar_mm}"\nmass_kg = 0.1', r"scale = 0\.001"),
        ('mesh = "nothere.obj"\nmass_kg = 0.1', "no such file"),
    ],
)
def test_bad_manifest_entries_stop_naming_the_entry(meshes, tmp_path, entry, pattern):
    text = "[thing]\n" + entry.format(**{k: v for k, v in meshes.items() if k != "dir"})
    m = _write_manifest(tmp_path / "bad.toml", text)
    with pytest.raises(ValidationError, match=pattern) as e:
        read_manifest(m)
    assert "'thing'" in str(e.value)
    with pytest.raises(ValidationError):
        use_objects(m)
    with pytest.raises(UnknownNameError):  # nothing was put in use
        object_spec("thing")


def test_manifest_paths_are_relative_to_the_manifest(meshes):
    m = _write_manifest(meshes["dir"] / "rel.toml", '[cubey]\nmesh = "cube5.obj"\nmass_kg = 0.03\n')
    (entry,) = read_manifest(m)
    assert entry.mesh.source == str(meshes["cube"])


def test_objects_dir_gives_catalogue_items_their_models(meshes, tmp_path):
    d = tmp_path / "models"
    d.mkdir()
    (d / "banana.obj").write_bytes(meshes["cube"].read_bytes())  # any closed model will do
    assert object_spec("banana").approximate
    assert object_geometry("banana").approximate
    use_objects(objects_dir=d)
    banana = object_spec("banana")
    assert banana.mesh is not None and not banana.approximate
    assert banana.mass_kg == OBJECTS["banana"].mass_kg  # the table's mass, the model's shape
    geom = object_geometry("banana")
    assert geom.is_mesh and not geom.approximate and geom.mass_kg == banana.mass_kg
    assert object_record("banana")["approximate"] is False
    assert object_spec("bowl").approximate  # no model given for it
    with pytest.raises(ValidationError, match="does not exist"):
        use_objects(objects_dir=tmp_path / "none")


# -- the mesh cube against the primitive cube -----------------------------------------------------


@pytest.mark.slow
def test_mesh_cube_retargets_and_resimulates_like_the_primitive_cube(meshes, tmp_path):
    """cube2 as a 5 cm mesh cube (convex, so MuJoCo collides the same box) gives the primitive
    cube's retargeting and re-simulation within: the same contact frames, keypoint error 0.1
    mm, kinematic penetration 1 mm, object error max 5 mm (the acceptance bound), both
    successful."""
    from retarget.hands import get_hand
    from retarget.retargeter import Retargeter
    from retarget.validate import Resimulator

    primitive = object_geometry("cube2")
    edge = primitive.aabb_half[0] * 2
    trimesh.creation.box((edge,) * 3).export(tmp_path / "cube.obj")
    use_objects(
        _write_manifest(
            tmp_path / "m.toml",
            f'[cube2]\nmesh = "{tmp_path / "cube.obj"}"\nmass_kg = {primitive.mass_kg}\n',
        )
    )
    mesh = object_geometry("cube2")
    assert mesh.is_mesh
    demo = generate_demo("cube2/tripod", "operator1", 0).trajectory
    hand = get_hand("shadow")
    out = {}
    for name, geom in (("primitive", primitive), ("mesh", mesh)):
        robot = Retargeter(hand, geom).retarget(demo)
        sim = Resimulator(hand, geom).run(robot.q_command, demo)
        out[name] = (robot, sim.metrics())
    (rp, mp), (rm, mm) = out["primitive"], out["mesh"]
    assert mp["success"] and mm["success"]
    # the same signed distance (exact for both), so the same contacts and keypoint targets
    np.testing.assert_array_equal(rp.contact_active, rm.contact_active)
    assert abs(rp.keypoint_err.mean() - rm.keypoint_err.mean()) < 1e-4
    # MuJoCo's box–capsule and mesh–capsule distances differ by up to a millimetre
    assert abs(rp.min_distance.min() - rm.min_distance.min()) < 1e-3
    assert abs(mp["object_pos_err_max_m"] - mm["object_pos_err_max_m"]) < 5e-3
    json.dumps(object_record("cube2"))  # the record outputs carry is JSON-ready


def test_convex_parts_of_a_convex_mesh_are_its_hull(meshes):
    (part,) = convex_parts(load_object_mesh(meshes["cube"]))
    assert len(part.vertices) == 8 and part.volume_m3 == pytest.approx(CUBE_EDGE**3)
    np.testing.assert_allclose(part.centroid, 0.0, atol=1e-12)
    # every plane's inside is the cube's: n·x + d ≤ 0 at the centre, = 0 at its face
    assert (part.planes[:, 3] < 0).all()


# -- the command lines --------------------------------------------------------------------------


def test_cli_refuses_bad_manifests_and_unknown_objects_before_any_work(meshes, tmp_path, capsys):
    from dexcanvas_core.cli import main as dexcanvas_main
    from retarget.cli import main as retarget_main

    bad = _write_manifest(
        tmp_path / "bad.toml", f'[w]\nmesh = "{meshes["open"]}"\nmass_kg = 0.05\n'
    )
    out = tmp_path / "run"
    rc = retarget_main(["run", "--hand", "shadow", "--pair", "w/tripod", "--objects", str(bad),
                        "--out", str(out)])  # fmt: skip
    err = capsys.readouterr().err
    assert rc == 2 and "object 'w'" in err and "not a closed surface" in err
    assert not out.exists()  # nothing was started
    rc = dexcanvas_main(["simulate", "--pair", "widget/tripod", "--out", str(tmp_path / "x.lance")])
    err = capsys.readouterr().err
    assert rc == 2 and "unknown object 'widget'" in err and "--objects MANIFEST" in err


@pytest.mark.slow
def test_retarget_run_with_a_mesh_manifest_records_the_object(meshes, tmp_path):
    """``retarget run --objects`` with cube2 given as a 5 cm mesh cube: the built-in
    demonstration is generated on the mesh, the run succeeds and metrics.json says which
    object shape was used."""
    from retarget.cli import main as retarget_main

    m = _write_manifest(
        tmp_path / "m.toml", f'[cube2]\nmesh = "{meshes["cube"]}"\nmass_kg = 0.037\n'
    )
    out = tmp_path / "run"
    rc = retarget_main(["run", "--hand", "shadow", "--pair", "cube2/tripod", "--objects", str(m),
                        "--out", str(out)])  # fmt: skip
    assert rc == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["success"] and metrics["approximate_object"] is False
    rec = metrics["object"]
    assert rec["shape_source"] == "mesh" and rec["mesh"] == str(meshes["cube"])
    assert rec["mass_kg"] == 0.037 and rec["convex_parts"] == 1


def test_inside_test_matches_the_parts_in_blocks(meshes):
    """The grid's inside test (per part, in blocks of points: bounded memory on real models
    with thousands of planes) agrees with testing every part's planes at once."""
    from dexcanvas_core.objects.sdf import _inside_any

    col = mesh_collision(load_object_mesh(meshes["bowl"]))
    rng = np.random.default_rng(3)
    p = rng.uniform(-0.09, 0.09, (10_000, 3)) + np.array([0.0, 0.0, 0.03])
    inside = col.sdf._inside(p)
    np.testing.assert_array_equal(inside, _inside_any(p, list(col.parts)))
    assert 0 < inside.sum() < len(p)
