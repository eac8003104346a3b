"""Props as colliders: loading (mesh files, USD), exact signed distance against trimesh, the
clearance search along capsule axes, held and animated props."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from usdhands.algorithms.interaction.clearance import axis_clearance
from usdhands.algorithms.interaction.colliders import Colliders, attached_xforms, mesh_collider
from usdhands.algorithms.interaction.proximity import MeshProximity, _barycentric
from usdhands.errors import AssetReadError
from usdhands.formats.props import check_prop_units, read_props
from usdhands.model.prop import PropMesh
from usdhands.samples.props import cup_mesh, cup_obj_text, cup_usda_text

ASSETS = Path(__file__).resolve().parent.parent.parent / "shared" / "assets"
MUG = ASSETS / "mujoco_mug" / "mug.obj"
TEAPOT = ASSETS / "usd_teapot" / "UtahTeapot.usd"


def _near_points(mesh: trimesh.Trimesh, n: int, spread: float, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    pts, _ = trimesh.sample.sample_surface(mesh, n, seed=seed)
    return pts + rng.normal(size=pts.shape) * spread


def _trimesh_of(prop: PropMesh) -> trimesh.Trimesh:
    return trimesh.Trimesh(np.asarray(prop.vertices), np.asarray(prop.faces), process=False)


def _trimesh_reference(mesh: trimesh.Trimesh, pts: np.ndarray) -> np.ndarray:
    """The naive answer: per closed body, trimesh's signed distance; the least over the bodies
    (negative inside any body).

    On the whole cup ``trimesh.proximity.signed_distance`` takes its sign from the nearest
    face, which is wrong inside the cup's wall where the handle's closed tube enters it,
    and measures to the tube's buried faces there.
    """
    out = np.full(len(pts), np.inf)
    for body in mesh.split(only_watertight=False):
        out = np.minimum(out, -trimesh.proximity.signed_distance(body, pts))
    return out


def test_fast_signed_distance_matches_trimesh_on_the_sample_cup():
    mesh = cup_mesh()
    pts = _near_points(mesh, 3000, 0.5)
    fast = MeshProximity(mesh.vertices, mesh.faces).signed_distance(pts)
    np.testing.assert_allclose(fast, _trimesh_reference(mesh, pts), atol=1e-6)
    assert (fast < 0).sum() > 300 and (fast > 0).sum() > 300  # both sides exercised
    # trimesh on the whole mesh: the sign is wrong at a few points in the wall where the handle enters
    whole = -trimesh.proximity.signed_distance(mesh, pts)
    assert 0.99 < np.mean(np.sign(fast) == np.sign(whole)) < 1.0


@pytest.mark.parametrize("shape", ["box", "cylinder"])
def test_sign_on_edges_and_on_shells_wound_inward_matches_trimesh(shape):
    """Points whose nearest surface point is on an edge or a corner (a box's and a cylinder's rims)
    take the side of the edge's pseudonormal or the winding number; a closed shell wound inward
    (every face reversed, as some exporters write) measures like the one wound outward."""
    mesh = trimesh.creation.box([2.0, 3.0, 4.0]) if shape == "box" else trimesh.creation.cylinder(1.5, 4.0, sections=24)
    pts = _near_points(mesh, 4000, 0.6, seed=3)
    reference = -trimesh.proximity.signed_distance(mesh, pts)
    outward = MeshProximity(mesh.vertices, mesh.faces)
    part = outward.parts[0]
    d, face, closest = part.distance(pts)
    on_edge = np.sum(_barycentric(closest, mesh.vertices[mesh.faces[face]]) <= 1e-6, axis=1) >= 1
    assert on_edge.sum() > 500  # edges and corners exercised
    np.testing.assert_allclose(outward.signed_distance(pts), reference, atol=1e-9)
    np.testing.assert_allclose(MeshProximity(mesh.vertices, mesh.faces[:, ::-1]).signed_distance(pts), reference,
                               atol=1e-9)


@pytest.mark.parametrize("shape", ["cup", "mug"])
def test_compiled_sign_and_morton_order_give_the_numpy_answers_bit_for_bit(shape):
    """The compiled side tests (numba's _proximity_kernel, and the one compiled ahead of time where it was
    built) equal the NumPy one, and a batch queried in Morton order equals its points queried one by one,
    on points near faces, on edges and on vertices, exactly on them and off them, inside and out."""
    from usdhands.algorithms.interaction._proximity_kernel import closed_shell_signs
    from usdhands.compiled import kernel_module

    built = kernel_module("algorithms.interaction._interaction_compiled")
    twins = [closed_shell_signs] + ([built.closed_shell_signs] if built is not None else [])

    if shape == "mug" and not MUG.exists():
        pytest.skip("shared assets not present")
    mesh = cup_mesh() if shape == "cup" else None
    if mesh is None:
        (prop,) = read_props(MUG, meters_per_unit=0.01, up_axis="Y", prop_meters_per_unit=0.01)
        mesh = _trimesh_of(prop)
    prox = MeshProximity(np.asarray(mesh.vertices), np.asarray(mesh.faces))
    rng = np.random.default_rng(3)
    for part in prox.parts:
        if not part.closed:
            continue
        V, F = part.vertices, part.faces
        scale = float(np.ptp(V, axis=0).max())
        edges = (V[F[:, 0]] + V[F[:, 1]]) / 2
        pts = np.concatenate([V, edges, V + rng.normal(scale=0.01 * scale, size=V.shape),
                              edges + rng.normal(scale=0.005 * scale, size=edges.shape),
                              _near_points(trimesh.Trimesh(V, F, process=False), 3000, 0.02 * scale)])
        pts = np.ascontiguousarray(pts)
        d, face, closest = part.distance(pts)
        expected = part._closed_signed(pts, d, face, closest)
        for signs in twins:
            got, rest = signs(pts, closest, face, d, part.normals, V, F, part.neighbours, part.flat)
            got[rest] = np.where(part._undecided_inside(pts[rest], face[rest], closest[rest], d[rest]), -d[rest],
                                 d[rest])
            assert rest.any() and (expected < 0).any() and (expected > 0).any()
            assert got.tobytes() == expected.tobytes()
        one_by_one = np.concatenate([part.distance(pts[i:i + 1])[0] for i in range(0, len(pts), 7)])
        assert one_by_one.tobytes() == d[::7].tobytes()  # batches of >= SORT_FROM points go in Morton order


@pytest.mark.parametrize("shape", ["cup", "mug", "box", "torus", "cylinder"])
def test_a_corner_takes_the_side_of_the_faces_around_it_where_they_agree(shape):
    """Points whose nearest surface point is a vertex (convex corners, and the saddles inside a torus):
    where every face around the vertex has the point on the same side, that side is the winding
    number's; the rest go to the winding number. A correction of such points builds no winding-number
    hierarchy at all."""
    if shape == "mug" and not MUG.exists():
        pytest.skip("shared assets not present")
    if shape == "mug":
        (prop,) = read_props(MUG, meters_per_unit=0.01, up_axis="Y", prop_meters_per_unit=0.01)
        mesh = _trimesh_of(prop)
    else:
        mesh = {"cup": cup_mesh, "box": lambda: trimesh.creation.box([2.0, 3.0, 4.0]),
                "torus": lambda: trimesh.creation.torus(1.0, 0.3),
                "cylinder": lambda: trimesh.creation.cylinder(1.5, 4.0, sections=12)}[shape]()
    rng = np.random.default_rng(5)
    part = MeshProximity(np.asarray(mesh.vertices), np.asarray(mesh.faces)).parts[0]
    assert part.closed
    V = part.vertices
    scale = float(np.ptp(V, axis=0).max())
    pts = np.concatenate([V[rng.integers(0, len(V), 4000)] + rng.normal(size=(4000, 3)) * s * scale
                          for s in (1e-4, 1e-2, 0.2)])
    d, face, closest = part.distance(pts)
    bary = np.stack(part._barycentric(closest, face), axis=1)
    corner = np.nonzero(((bary <= 1e-6).sum(axis=1) >= 2) & (d > 0))[0]
    assert len(corner) > 200
    vertex = part.faces[face[corner], np.argmax(bary[corner], axis=1)]
    sure, inside = part._corner_sides(pts[corner], closest[corner], d[corner], vertex)
    winding = part._parity(pts[corner])
    assert sure.mean() > 0.95 and (~inside[sure]).any()
    if shape in ("cup", "mug"):  # reflex corners (the rim, the handle's joins): points inside nearest a vertex
        assert inside[sure].any()
    np.testing.assert_array_equal(inside[sure], winding[sure])
    # the whole query: the same signs as the winding number gives, without building its hierarchy
    fresh = MeshProximity(np.asarray(mesh.vertices), np.asarray(mesh.faces)).parts[0]
    signed = fresh.signed_distance(pts[corner][sure])
    np.testing.assert_array_equal(signed < 0, winding[sure])
    assert fresh._fwn is None


@pytest.mark.skipif(not MUG.exists(), reason="shared assets not present")
def test_mug_loads_closed_and_fast_distance_matches_trimesh():
    (prop,) = read_props(MUG, meters_per_unit=0.01, up_axis="Y")
    mesh = _trimesh_of(prop)
    assert len(prop.faces) == 24544
    assert mesh.is_watertight  # split along normals as loaded; merged into one closed body
    assert mesh.bounds[1][1] == pytest.approx(7.19, abs=0.01)  # cm, Y up
    pts = _near_points(mesh, 3000, 0.7, seed=1)
    fast = MeshProximity(prop.vertices, prop.faces).signed_distance(pts)
    np.testing.assert_allclose(fast, _trimesh_reference(mesh, pts), atol=1e-6)


@pytest.mark.skipif(not TEAPOT.exists(), reason="shared assets not present")
def test_teapot_loads_in_the_clips_units_and_up_axis_and_its_sign_comes_from_the_winding_number():
    (m_prop,) = read_props(TEAPOT, meters_per_unit=1.0, up_axis="Y")
    (cm_prop,) = read_props(TEAPOT, meters_per_unit=0.01, up_axis="Z")
    np.testing.assert_allclose(m_prop.vertices[:, 1].max(), 0.2296, atol=1e-3)  # metres, Y up
    # centimetres, Z up: (x, y, z) -> 100 * (x, -z, y)
    np.testing.assert_allclose(cm_prop.vertices, 100 * m_prop.vertices[:, [0, 2, 1]] * [1, -1, 1], atol=1e-4)
    mesh = _trimesh_of(m_prop)
    assert not mesh.is_watertight
    pts = _near_points(mesh, 3000, 0.01, seed=2)
    prox = MeshProximity(m_prop.vertices, m_prop.faces)
    fast = prox.signed_distance(pts)
    ref = -trimesh.proximity.signed_distance(mesh, pts)
    # distances exact: equal to trimesh's on 99% of points; on the rest trimesh's candidate search
    # missed the nearest face (a brute-force check over all faces agrees with libigl)
    assert np.all(np.abs(fast) <= np.abs(ref) + 1e-9)
    assert np.mean(np.isclose(np.abs(fast), np.abs(ref), rtol=0, atol=1e-9)) > 0.99
    assert np.mean(np.sign(fast) == np.sign(ref)) > 0.97  # trimesh's sign is wrong near the holes
    # the winding number is right where it is unambiguous: the belly of the pot and far outside
    assert prox.signed_distance(np.array([[0.0, 0.08, 0.0]]))[0] < -0.05
    assert prox.signed_distance(np.array([[0.0, 0.08, 0.5]]))[0] > 0.2


def test_sample_cup_obj_and_usda_load_alike(tmp_path):
    (tmp_path / "cup.obj").write_text(cup_obj_text())
    (tmp_path / "cup.usda").write_text(cup_usda_text())
    (obj,) = read_props(tmp_path / "cup.obj", meters_per_unit=0.01, up_axis="Y")
    (usd,) = read_props(tmp_path / "cup.usda", meters_per_unit=1.0, up_axis="Y")
    np.testing.assert_allclose(np.sort(obj.vertices, axis=0) / 100, np.sort(usd.vertices, axis=0), atol=1e-6)
    assert len(obj.faces) == len(usd.faces) == len(cup_mesh().faces)


def test_animated_usd_prop_keeps_its_keys(tmp_path):
    text = cup_usda_text().replace('def Xform "Cup" (\n    kind = "component"\n)\n{',
                                   'def Xform "Cup" (\n    kind = "component"\n)\n{\n'
                                   '    double3 xformOp:translate.timeSamples = {0: (0, 0, 0), 24: (0, 100, 0)}\n'
                                   '    uniform token[] xformOpOrder = ["xformOp:translate"]\n')
    text = text.replace("upAxis", "timeCodesPerSecond = 24\n    upAxis")
    (tmp_path / "moving.usda").write_text(text)
    (prop,) = read_props(tmp_path / "moving.usda", meters_per_unit=1.0, up_axis="Y")
    assert prop.animated
    np.testing.assert_allclose(prop.times, [0.0, 1.0])
    x = prop.xforms_at(np.array([0.0, 0.5, 1.0, 2.0]))
    np.testing.assert_allclose(x[:, 1, 3], [0.0, 0.5, 1.0, 1.0])  # 100 cm in a metre clip, held after the end
    col = mesh_collider(prop, np.array([0.0, 1.0]))
    below = np.array([[0.0, -0.01, 0.0], [0.0, 0.99, 0.0]])  # 1 cm under the base at rest, and once it rose
    np.testing.assert_allclose(col.signed_distance(np.array([0, 1]), below), [0.01, 0.01], atol=1e-6)
    assert col.signed_distance(np.array([1]), below[:1])[0] > 0.9


@pytest.mark.parametrize("content,suffix,message", [
    ("this is not a mesh at all\n", ".obj", "no triangles"),
    ("", ".obj", "no triangles"),
    ("solid empty\nendsolid empty\n", ".stl", "no triangles"),
    ("v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n", ".obj", "degenerate"),
    ("hello", ".xyz", "unknown prop format"),
])
def test_bad_prop_files_are_refused_in_one_line(tmp_path, content, suffix, message):
    p = tmp_path / f"bad{suffix}"
    p.write_text(content)
    with pytest.raises(AssetReadError) as e:
        read_props(p, meters_per_unit=1.0, up_axis="Y")
    assert message in str(e.value) and str(p) in str(e.value) and "\n" not in str(e.value)


def test_a_prop_in_other_units_than_it_claims_is_refused():
    character = np.array([[-0.5, 0.0, -0.3], [0.5, 1.8, 0.3]])  # metres
    cup_cm = cup_mesh().vertices + [30.0, 90.0, 20.0]  # a cup in front of the chest, in cm
    wrong = PropMesh("Cup", cup_cm, cup_mesh().faces, path="cup.glb")  # read as metres
    with pytest.raises(AssetReadError, match="looks like it is in centimetres"):
        check_prop_units(wrong, character, 1.0, 1.0)
    check_prop_units(PropMesh("Cup", cup_cm / 100, cup_mesh().faces), character, 1.0, 1.0)  # fine in metres
    far = PropMesh("Far", cup_mesh().vertices / 100 + [5.0, 0.0, 0.0], cup_mesh().faces)
    check_prop_units(far, character, 1.0, 1.0)  # a real cup 5 m away is no unit slip


def _sphere_colliders(radius=1.0, centre=(0.0, 0.0, 0.0)):
    s = trimesh.creation.icosphere(subdivisions=4, radius=radius)
    prop = PropMesh("ball", s.vertices + centre, s.faces)
    return Colliders([mesh_collider(prop, np.zeros(1))]), s


def test_clearance_search_finds_a_contact_between_far_end_points():
    cols, _ = _sphere_colliders()
    # a long axis whose ends are 10 units away but whose middle passes 0.2 from the ball
    a = np.array([[-10.0, 1.2, 0.0], [-10.0, 3.0, 0.0]])
    b = np.array([[10.0, 1.2, 0.0], [10.0, 3.0, 0.0]])
    lower, upper = axis_clearance(cols, np.zeros(2, int), a, b, need=np.array([0.5, 0.5]), resolution=0.01,
                                  find_depth=True)
    assert upper[0] < 0.5 and lower[0] <= 0.2 <= upper[0] + 1e-9 and upper[0] - lower[0] <= 0.02
    assert lower[1] >= 0.5  # 2 units above the ball: clear
    # the clearance test (not the depth search) fails the first and passes the second
    lower, upper = axis_clearance(cols, np.zeros(2, int), a, b, need=np.array([0.5, 0.5]), resolution=0.01)
    assert upper[0] < 0.5 and lower[1] >= 0.5


def test_clearance_search_agrees_with_dense_sampling_on_random_axes():
    cols, s = _sphere_colliders()
    rng = np.random.default_rng(3)
    n = 100
    dirs = rng.normal(size=(n, 3))
    a = dirs / np.linalg.norm(dirs, axis=1, keepdims=True) * rng.uniform(0.8, 1.6, size=(n, 1))
    b = a + rng.normal(size=(n, 3)) * 0.6
    lower, upper = axis_clearance(cols, np.zeros(n, int), a, b, need=np.full(n, 0.3), resolution=0.005,
                                  find_depth=True)
    t = np.linspace(0, 1, 201)
    dense = a[:, None] + t[None, :, None] * (b - a)[:, None]
    true = (-trimesh.proximity.signed_distance(s, dense.reshape(-1, 3))).reshape(n, -1).min(axis=1)
    below = true < 0.3
    assert below.sum() >= 20
    assert np.all(lower[below] <= true[below] + 1e-6) and np.all(upper[below] >= true[below] - 1e-3)
    assert np.all(upper[below] - lower[below] <= 0.0051)
    assert np.all(lower[~below] >= 0.3 - 0.0025)


@pytest.mark.skipif(not MUG.exists(), reason="shared assets not present")
def test_within_gives_the_thresholded_signed_distance_with_fewer_exact_queries():
    """``Colliders.within`` (the wrist's proximity cut) answers ``signed_distance(f, p, r) < r`` exactly:
    on the mug (a moving placement, a uniform scale), an unused vertex far out that must not count as
    surface, and a ball; points inside, on both sides of ``r`` and right at it."""
    (prop,) = read_props(MUG, meters_per_unit=0.01, up_axis="Y")
    verts = np.vstack([prop.vertices, [[-15.0, -15.0, -15.0]]])  # a vertex of no face, among the points
    T = 5
    world = np.tile(np.eye(4), (T, 1, 1))
    world[:, :3, :3] *= 1.5
    world[:, 0, 3] = np.arange(T) * 3.0
    mug = mesh_collider(PropMesh("mug", verts, prop.faces), np.zeros(T), world=world)
    ball, _ = _sphere_colliders(radius=2.0, centre=(0.0, 40.0, 0.0))
    cols = Colliders([mug, *ball.items])
    rng = np.random.default_rng(4)
    frames = rng.integers(0, T, size=5000)
    surface = _near_points(_trimesh_of(prop), 1000, 0.5, seed=5) * 1.5 + world[frames[:1000], :3, 3]
    pts = np.vstack([surface, rng.uniform(-30.0, 45.0, size=(4000, 3))])
    r = 12.0
    exact = cols.signed_distance(frames, pts)
    # points whose distance is r itself, to the last bit, and just either side of it
    edge = np.nonzero(np.abs(exact - r) < 3.0)[0][:20]
    assert len(edge) == 20
    q0 = mug.exact_queries
    want = cols.signed_distance(frames, pts, r) < r
    q1 = mug.exact_queries
    got = cols.within(frames, pts, r)
    np.testing.assert_array_equal(got, want)
    assert mug.exact_queries - q1 < 0.7 * (q1 - q0)  # the vertex bound decides many of them
    assert got.sum() > 1000 and (~got).sum() > 1000 and (exact < 0).sum() > 200  # inside, near and far all met
    for rr in (exact[edge], np.nextafter(exact[edge], np.inf), np.nextafter(exact[edge], -np.inf)):
        for k, i in enumerate(edge):
            assert cols.within(frames[i:i + 1], pts[i:i + 1], rr[k])[0] == (exact[i] < rr[k])


def test_attached_prop_moves_with_the_joint():
    T = 10
    joint = np.tile(np.eye(4), (T, 1, 1))
    joint[:, 0, 3] = np.arange(T) * 0.1  # the hand moves along x
    prop = np.tile(np.eye(4), (T, 1, 1))
    prop[:, 1, 3] = 1.0
    out = attached_xforms(prop, joint, 3, 6)
    np.testing.assert_allclose(out[:3, 0, 3], 0.0, atol=1e-12)  # before it is picked up: where the file puts it
    np.testing.assert_allclose(out[3:7, 0, 3], joint[3:7, 0, 3] - 0.3, atol=1e-12)  # held: the offset it had at frame 3
    np.testing.assert_allclose(out[7:, 0, 3], out[6, 0, 3])  # put down where it was left
    np.testing.assert_allclose(out[:, 1, 3], 1.0)


def _animated_cup_glb(path):
    """The sample cup (scaled to metres) as a glTF node rising 1 m over 1 s (a LINEAR translation channel)."""
    import pygltflib

    cup = cup_mesh()
    cup.apply_scale(0.01)
    cup.export(path)
    g = pygltflib.GLTF2().load(str(path))
    blob = bytearray(g.binary_blob())
    node = next(i for i, n in enumerate(g.nodes) if n.mesh is not None)
    times = np.array([0.0, 1.0], dtype=np.float32).tobytes()
    moves = np.array([[0, 0, 0], [0, 1, 0]], dtype=np.float32).tobytes()
    views = []
    for data in (times, moves):
        while len(blob) % 4:
            blob.append(0)
        views.append(len(g.bufferViews))
        g.bufferViews.append(pygltflib.BufferView(buffer=0, byteOffset=len(blob), byteLength=len(data)))
        blob.extend(data)
    g.accessors.append(pygltflib.Accessor(bufferView=views[0], componentType=5126, count=2, type="SCALAR",
                                          min=[0.0], max=[1.0]))
    g.accessors.append(pygltflib.Accessor(bufferView=views[1], componentType=5126, count=2, type="VEC3"))
    n = len(g.accessors)
    g.animations = [pygltflib.Animation(
        samplers=[pygltflib.AnimationSampler(input=n - 2, output=n - 1, interpolation="LINEAR")],
        channels=[pygltflib.AnimationChannel(sampler=0, target=pygltflib.AnimationChannelTarget(
            node=node, path="translation"))])]
    g.buffers[0].byteLength = len(blob)
    g.set_binary_blob(bytes(blob))
    g.save(str(path))


def test_animated_gltf_prop_keeps_its_node_animation(tmp_path):
    _animated_cup_glb(tmp_path / "rising.glb")
    (prop,) = read_props(tmp_path / "rising.glb", meters_per_unit=0.01, up_axis="Y")  # a cm clip
    assert prop.animated
    np.testing.assert_allclose(prop.times, [0.0, 1.0])
    x = prop.xforms_at(np.array([0.0, 0.5, 1.0]))
    np.testing.assert_allclose(x[:, 1, 3], [0.0, 50.0, 100.0], atol=1e-4)  # 1 m = 100 cm, linear
    assert np.asarray(prop.vertices)[:, 1].max() == pytest.approx(9.5, abs=1e-3)  # the cup in cm


def test_shells_are_the_components_of_faces_sharing_vertices():
    """_shells (components of the vertex graph) against the definition (components of the graph of faces
    sharing a vertex), on soups of spheres with shuffled faces and unused vertices and the split mug:
    the same shells, in the order of their first face, each in increasing order."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    from usdhands.algorithms.interaction.proximity import _shells

    def reference(faces, n_vertices):
        F = len(faces)
        incidence = coo_matrix((np.ones(3 * F), (np.repeat(np.arange(F), 3), faces.reshape(-1))),
                               shape=(F, n_vertices)).tocsr()
        n, labels = connected_components(incidence @ incidence.T, directed=False)
        order = np.argsort(labels, kind="stable")
        return np.split(order, np.cumsum(np.bincount(labels, minlength=n))[:-1])

    rng = np.random.default_rng(0)
    cases = []
    for _ in range(20):
        parts, offset = [], 0
        for _ in range(rng.integers(1, 8)):
            sphere = trimesh.creation.icosphere(subdivisions=int(rng.integers(0, 3)))
            parts.append(sphere.faces + offset)
            offset += len(sphere.vertices) + int(rng.integers(0, 3))
        faces = np.concatenate(parts)
        cases.append((faces[rng.permutation(len(faces))], offset))
    mesh = cup_mesh()
    cases.append((np.asarray(mesh.faces), len(mesh.vertices)))
    many = 0
    for faces, n_vertices in cases:
        faces = np.asarray(faces, dtype=np.int64)
        got, want = _shells(faces, n_vertices), reference(faces, n_vertices)
        assert len(got) == len(want) and all(np.array_equal(g, w) for g, w in zip(got, want))
        many += len(want) > 2
    assert many > 5
