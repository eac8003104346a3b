"""The props' geometry compiled ahead of time, which lets a correction against closed props import
neither libigl nor SciPy: the triangle tree's nearest points against a brute force written here and
against libigl, the union-find shells against SciPy's components, the banded Cholesky against
``scipy.linalg.solveh_banded``, and a fresh process's imports."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh

from usdhands.algorithms.interaction import proximity, smoothing
from usdhands.compiled import kernel_module
from usdhands.formats.props import read_props
from usdhands.samples.props import cup_mesh

ROOT = Path(__file__).resolve().parent.parent
MUG = ROOT.parent / "shared" / "assets" / "mujoco_mug" / "mug.obj"
TEAPOT = ROOT.parent / "shared" / "assets" / "usd_teapot" / "UtahTeapot.usd"
BUILT = kernel_module("algorithms.interaction._interaction_compiled")
needs_built = pytest.mark.skipif(BUILT is None, reason="the interaction's kernels were not compiled at install")


def _segment_nearest(p, a, b):
    """Nearest points ``(N, F, 3)`` of segments ``a b`` ``(F, 3)`` to points ``p`` ``(N, 3)``."""
    e = b - a
    ee = np.einsum("fj,fj->f", e, e)
    t = np.einsum("nfj,fj->nf", p[:, None] - a[None], e) / np.where(ee > 0, ee, 1.0)
    t = np.clip(np.where(ee > 0, t, 0.0), 0.0, 1.0)
    return a[None] + t[..., None] * e[None]


def brute_force_nearest(vertices, faces, p):
    """Least squared distance ``(N,)`` from each point to every triangle: the projection on the plane where it
    falls inside (all barycentric coordinates >= 0), else the nearest point of the three edges; a triangle
    without area by its edges only. Written apart from the kernel's region tests."""
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    n = np.cross(b - a, c - a)
    nn = np.einsum("fj,fj->f", n, n)
    flat = nn <= 0
    cands = [_segment_nearest(p, a, b), _segment_nearest(p, b, c), _segment_nearest(p, c, a)]
    dist = [np.einsum("nfj,nfj->nf", p[:, None] - q, p[:, None] - q) for q in cands]
    best = np.minimum(np.minimum(dist[0], dist[1]), dist[2])
    h = np.einsum("nfj,fj->nf", p[:, None] - a[None], n) / np.where(flat, 1.0, nn)
    proj = p[:, None] - h[..., None] * n[None]
    # barycentric coordinates of the projection by signed areas
    w_a = np.einsum("nfj,fj->nf", np.cross(c[None] - b[None], proj - b[None]), n)
    w_b = np.einsum("nfj,fj->nf", np.cross(a[None] - c[None], proj - c[None]), n)
    w_c = np.einsum("nfj,fj->nf", np.cross(b[None] - a[None], proj - a[None]), n)
    inside = (w_a >= 0) & (w_b >= 0) & (w_c >= 0) & ~flat[None]
    plane = np.einsum("nfj,nfj->nf", p[:, None] - proj, p[:, None] - proj)
    return np.where(inside, np.minimum(plane, best), best).min(axis=1)


def _soup(seed: int):
    """Random triangles, some without area (a repeated corner, three corners on a line), and points around."""
    rng = np.random.default_rng(seed)
    V = rng.normal(size=(120, 3))
    F = rng.integers(0, len(V), size=(200, 3))
    F[:10, 2] = F[:10, 0]  # a repeated corner
    V[F[10:20, 2]] = 0.3 * V[F[10:20, 0]] + 0.7 * V[F[10:20, 1]]  # a corner on the opposite edge's line
    P = np.concatenate([rng.normal(size=(300, 3)) * 1.5, V[rng.integers(0, len(V), 50)]])
    return V, F.astype(np.int64), P


@needs_built
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_tree_gives_the_brute_force_nearest_point_on_triangle_soups(seed):
    V, F, P = _soup(seed)
    d2, face, near = BUILT.TriangleTree(V, F).squared_distance(P)
    np.testing.assert_allclose(d2, brute_force_nearest(V, F, P), rtol=1e-10, atol=1e-14)
    # the nearest point is that distance away and lies on the face named
    np.testing.assert_allclose(np.einsum("ij,ij->i", P - near, P - near), d2, rtol=1e-12, atol=1e-14)
    for i in range(0, len(P), 7):  # coordinates of about 1: on the face to rounding
        assert brute_force_nearest(V, F[face[i]][None], near[i][None])[0] <= 1e-24
    # visited in Z order (sort_from 0): the same answers to the bit
    sorted_answers = BUILT.TriangleTree(V, F).squared_distance(P, 0)
    assert all(x.tobytes() == y.tobytes() for x, y in zip(sorted_answers, (d2, face, near)))


@needs_built
@pytest.mark.parametrize("n_faces", [1, 2, 4, 5, 9, 17])
def test_tree_of_a_few_triangles_is_exact(n_faces):
    """Trees of one leaf, of a leaf and a split, of a few levels: the brute force's distances."""
    rng = np.random.default_rng(n_faces)
    V = rng.normal(size=(3 * n_faces, 3))
    F = np.arange(3 * n_faces, dtype=np.int64).reshape(n_faces, 3)
    P = rng.normal(size=(300, 3)) * 2
    for sort_from in (-1, 0):
        d2, _, _ = BUILT.TriangleTree(V, F).squared_distance(P, sort_from)
        np.testing.assert_allclose(d2, brute_force_nearest(V, F, P), rtol=1e-10, atol=1e-14)


@needs_built
def test_tree_is_exact_on_the_sample_cup_and_the_real_props_against_libigl():
    import igl

    meshes = [cup_mesh()]
    if MUG.exists():
        (mug,) = read_props(MUG, meters_per_unit=0.01, up_axis="Y", prop_meters_per_unit=0.01)
        meshes.append(trimesh.Trimesh(mug.vertices, mug.faces, process=False))
    if TEAPOT.exists():
        (pot,) = read_props(TEAPOT, meters_per_unit=1.0, up_axis="Y")
        meshes.append(trimesh.Trimesh(pot.vertices, pot.faces, process=False))
    for mesh in meshes:
        V = np.ascontiguousarray(mesh.vertices, dtype=np.float64)
        F = np.ascontiguousarray(mesh.faces, dtype=np.int64)
        scale = float(np.ptp(V, axis=0).max())
        rng = np.random.default_rng(4)
        P, _ = trimesh.sample.sample_surface(mesh, 4000, seed=5)
        P = np.concatenate([P + rng.normal(size=P.shape) * scale * 0.05, V[:200],
                            rng.uniform(-2, 2, size=(500, 3)) * scale])
        d2, face, near = BUILT.TriangleTree(V, F).squared_distance(P)
        tree = igl.AABB()
        tree.init(V, F)
        e2, _, _ = tree.squared_distance(V, F, P)
        np.testing.assert_allclose(d2, e2, rtol=1e-9, atol=1e-24 * scale ** 2 + 1e-15 * scale ** 2)
        # each point's answer is its own: shuffled, the same faces and points to the bit
        order = rng.permutation(len(P))
        d2s, faces_s, near_s = BUILT.TriangleTree(V, F).squared_distance(P[order])
        assert d2s.tobytes() == d2[order].tobytes() and np.array_equal(faces_s, face[order])
        assert near_s.tobytes() == near[order].tobytes()


@needs_built
def test_tree_refuses_bad_meshes_and_gives_nan_for_nan_points():
    V, F, _ = _soup(0)
    with pytest.raises(ValueError, match=r"expected vertices \(V, 3\) and faces \(F, 3\)"):
        BUILT.TriangleTree(V, F[:0])
    with pytest.raises(ValueError, match="faces index vertices that do not exist"):
        BUILT.TriangleTree(V, F + len(V))
    d2, face, near = BUILT.TriangleTree(V, F).squared_distance(np.array([[np.nan, 0.0, 0.0], [0.0, 0.0, 0.0]]))
    assert np.isnan(d2[0]) and np.isnan(near[0]).all() and face[0] == 0
    assert d2[1] == pytest.approx(brute_force_nearest(V, F, np.zeros((1, 3)))[0], rel=1e-10)


@needs_built
@pytest.mark.skipif(not MUG.exists(), reason="shared assets not present")
def test_signed_distances_with_the_tree_equal_libigl_s(monkeypatch):
    """MeshProximity with the compiled tree and with libigl's (the install without a compiler): the same
    signed distances to rounding, on the mug's points near and far."""
    (mug,) = read_props(MUG, meters_per_unit=0.01, up_axis="Y", prop_meters_per_unit=0.01)
    mesh = trimesh.Trimesh(mug.vertices, mug.faces, process=False)
    P, _ = trimesh.sample.sample_surface(mesh, 5000, seed=8)
    P = P + np.random.default_rng(8).normal(size=P.shape) * 0.5
    fast = proximity.MeshProximity(mug.vertices, mug.faces).signed_distance(P)
    monkeypatch.setattr(proximity, "_compiled_geometry", lambda: None)
    with_igl = proximity.MeshProximity(mug.vertices, mug.faces).signed_distance(P)
    np.testing.assert_allclose(fast, with_igl, rtol=0, atol=1e-9)
    assert np.array_equal(np.sign(fast), np.sign(with_igl))


@pytest.mark.parametrize("compiled", [True, False])
def test_shells_by_union_find_are_scipy_s_components(monkeypatch, compiled):
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    if compiled and BUILT is None:
        pytest.skip("the interaction's kernels were not compiled at install")
    if not compiled:
        monkeypatch.setattr(proximity, "_compiled_geometry", lambda: None)
    rng = np.random.default_rng(11)
    for _ in range(30):
        n = int(rng.integers(3, 200))
        faces = rng.integers(0, n, size=(int(rng.integers(1, n)), 3)).astype(np.int64)
        if BUILT is not None:
            labels = BUILT.vertex_components(faces, n)
            graph = coo_matrix((np.ones(3 * len(faces)), (faces.reshape(-1), faces[:, [1, 2, 0]].reshape(-1))),
                               shape=(n, n))
            _, want = connected_components(graph, directed=False)
            # the same partition: labels map one to one
            pairs = np.unique(np.stack([labels, want], axis=1), axis=0)
            assert len(pairs) == len(np.unique(labels)) == len(np.unique(want))
            assert np.all(labels <= np.arange(n))  # each labelled by its smallest vertex
        shells = proximity._shells(faces, n)
        assert np.array_equal(np.sort(np.concatenate(shells)), np.arange(len(faces)))


@needs_built
def test_banded_cholesky_solves_what_scipy_solves_and_refuses_what_it_refuses():
    from scipy.linalg import solveh_banded

    rng = np.random.default_rng(12)
    for n in (1, 2, 3, 5, 60, 1800):
        ab = np.zeros((3, n))
        ab[2] = rng.uniform(1.0, 3.0, n) + 1234.5 * 6.0
        ab[1, 1:] = 1234.5 * -4.0 + rng.normal(size=n - 1)
        ab[0, 2:] = 1234.5 + rng.normal(size=max(n - 2, 0))
        b = rng.normal(size=n) * 100
        got = BUILT.solve_pentadiagonal_spd(ab, b)
        np.testing.assert_allclose(got, solveh_banded(ab, b), rtol=1e-10, atol=1e-12 * np.abs(got).max())
    bad = np.array([[0.0, 0.0, 3.0], [0.0, 2.0, 2.0], [1.0, 1.0, 1.0]])  # not positive definite
    with pytest.raises(np.linalg.LinAlgError) as theirs:
        solveh_banded(bad, np.ones(3))
    with pytest.raises(np.linalg.LinAlgError, match="leading minor not positive definite") as ours:
        BUILT.solve_pentadiagonal_spd(bad, np.ones(3))
    assert str(ours.value) == str(theirs.value)  # the same minor, in the same words


def test_second_difference_bands_and_product_are_the_sparse_matrix_s():
    from scipy import sparse

    rng = np.random.default_rng(13)
    for T in (3, 4, 9, 300):
        D = sparse.diags([np.ones(T - 2), -2 * np.ones(T - 2), np.ones(T - 2)], [0, 1, 2], shape=(T - 2, T))
        G = (D.T @ D).toarray()
        bands = smoothing._second_difference_bands(T)
        for k in range(3):
            assert np.array_equal(bands[k], np.diagonal(G, k))
        y = rng.normal(size=T)
        np.testing.assert_allclose(smoothing._banded_product(bands, y), G @ y, rtol=1e-13, atol=1e-12)


@needs_built
def test_bounded_smoother_gives_scipy_s_answer_with_the_compiled_solve(monkeypatch):
    rng = np.random.default_rng(14)
    lower = np.maximum(0.0, np.convolve(rng.normal(size=700), np.ones(25) / 5, mode="same"))
    weight = smoothing.smoothness_weight(30.0, 0.2)
    ours = smoothing.bounded_smooth(lower, lower + 2.0, weight)
    monkeypatch.setattr(smoothing, "_solve_banded", lambda ab, rhs: __import__("scipy.linalg").linalg.solveh_banded(
        ab, rhs))
    np.testing.assert_allclose(ours, smoothing.bounded_smooth(lower, lower + 2.0, weight), rtol=0, atol=1e-9)
    assert np.all(ours >= lower)


@needs_built
def test_a_correction_against_a_closed_prop_imports_neither_scipy_nor_libigl():
    """libigl's module imports SciPy's sparse module (with SciPy's array API layer: about 0.1 s of a fresh
    process); a correction against the sample cup and table (closed shells) needs neither."""
    code = (
        "import sys\n"
        "from pathlib import Path\n"
        "from usdhands.jobs.correction import CorrectOptions, correct\n"
        "import tempfile\n"
        "root = Path(sys.argv[1])\n"
        "with tempfile.TemporaryDirectory() as tmp:\n"
        "    props = (root / 'sample_assets/props/cup_on_table.obj', root / 'sample_assets/props/table.obj')\n"
        "    correct(root / 'sample_assets/interaction/cup_grasp.glb', Path(tmp) / 'out.glb',\n"
        "            CorrectOptions(props=props, attach=('cup_on_table=RightHand:48-102',)))\n"
        "print(sorted({m.split('.')[0] for m in sys.modules} & {'scipy', 'igl', 'numba', 'trimesh'}))\n")
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    out = subprocess.run([sys.executable, "-c", code, str(ROOT)], capture_output=True, text=True, env=env)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"


@needs_built
@pytest.mark.parametrize("shape", ["cup", "mug", "torus", "box"])
def test_compiled_corner_sides_give_the_numpy_answers_bit_for_bit(monkeypatch, shape):
    """The side of points the side test leaves undecided (nearest a vertex, on a flat face, on a plane), in one
    compiled pass, against the NumPy steps: the same insides and the same points left to the winding
    number, on points near vertices at three scales, inside and out (convex corners, the saddles of a
    torus, the cup's reflex rim)."""
    if shape == "mug" and not MUG.exists():
        pytest.skip("shared assets not present")
    if shape == "mug":
        (prop,) = read_props(MUG, meters_per_unit=0.01, up_axis="Y", prop_meters_per_unit=0.01)
        mesh = trimesh.Trimesh(prop.vertices, prop.faces, process=False)
    else:
        mesh = {"cup": cup_mesh, "box": lambda: trimesh.creation.box([2.0, 3.0, 4.0]),
                "torus": lambda: trimesh.creation.torus(1.0, 0.3)}[shape]()
    part = proximity.MeshProximity(np.asarray(mesh.vertices), np.asarray(mesh.faces)).parts[0]
    V = part.vertices
    scale = float(np.ptp(V, axis=0).max())
    rng = np.random.default_rng(6)
    pts = np.concatenate([V[rng.integers(0, len(V), 3000)] + rng.normal(size=(3000, 3)) * s * scale
                          for s in (1e-9, 1e-4, 1e-2, 0.2)] + [V[:300]])
    d, face, closest = part.distance(pts)
    normals, pad, unusable = part._corners_around()
    inside, todo = BUILT.undecided_sides(pts, closest, face, d, V, part.faces, normals, pad, unusable)
    # the NumPy steps of _undecided_inside, with the winding number recorded instead of asked
    u, v, w = part._barycentric(closest, face)
    corner = ((u <= 1e-6).astype(np.int8) + (v <= 1e-6) + (w <= 1e-6)) >= 2
    want_todo = ~corner
    want_inside = np.zeros(len(pts), dtype=bool)
    k = np.nonzero(corner)[0]
    slot = np.where(u[k] >= v[k], np.where(u[k] >= w[k], 0, 2), np.where(v[k] >= w[k], 1, 2))
    sure, behind = part._corner_sides(pts[k], closest[k], d[k], part.faces[face[k], slot])
    want_inside[k] = behind
    want_todo[k[~sure]] = True
    assert corner.sum() > 500 and sure.sum() > 400 and behind[sure].sum() + (~behind[sure]).sum() == sure.sum()
    assert np.array_equal(todo, want_todo)
    assert np.array_equal(inside[~todo], want_inside[~todo])
    # and through the method: the compiled pass, then the winding number for what it left
    monkeypatch.setattr(proximity, "_compiled_geometry", lambda: None)
    numpy_answer = part._undecided_inside(pts, face, closest, d)
    monkeypatch.undo()
    assert np.array_equal(part._undecided_inside(pts, face, closest, d), numpy_answer)
