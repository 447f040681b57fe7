"""Adaptive refinement of twisted / undulated leaves on their 3-D surface (issue 16)."""

from __future__ import annotations

import numpy as np
import pytest

from biomorph.errors import ParameterError
from biomorph.leaf.mesh import LeafBatch, leaf_grid
from biomorph.leaf.reduction import adaptive_mesh, reduced_mesh, surface_error
from biomorph.leaf.refine import (
    _orient,
    adaptive_faces,
    make_nodes,
    point_triangle_distance,
)
from biomorph.leaf.shape import LeafShape


def _nodes(shape, n_s=41, n_u=9):
    s, u = np.linspace(0, 1, n_s), np.linspace(-0.5, 0.5, n_u)
    b = LeafBatch.from_shapes([shape], s=s)
    return make_nodes(leaf_grid(b, u)[0], s, u, b.width[0])


def _check_triangulation(nodes, faces) -> None:
    """Faces tile the flat domain: all counter-clockwise, their domain areas add up to the
    domain's, every interior edge is shared by exactly two faces."""
    d = nodes.domain
    orient = np.array([_orient(d, *f) for f in faces])
    assert (orient > 0).all()
    s = np.linspace(0, 1, 2001)
    kind = nodes.kind
    rho = {0: np.ones_like(s), 1: 1 - s, 2: s, 3: 1 - np.abs(2 * s - 1)}[kind]
    assert orient.sum() / 2 == pytest.approx(np.trapezoid(rho, s), rel=1e-3)
    edges: dict[tuple[int, int], int] = {}
    for f in faces:
        for k in range(3):
            e = tuple(sorted((int(f[k]), int(f[(k + 1) % 3]))))
            edges[e] = edges.get(e, 0) + 1
    assert set(edges.values()) <= {1, 2}
    bnd = [e for e, c in edges.items() if c == 1]
    assert all(nodes.boundary[a] or nodes.boundary[b] or a in nodes.start for a, b in bnd)


@pytest.mark.parametrize(
    "shape",
    [
        LeafShape.from_preset("maize"),  # open base, closed tip
        LeafShape.parametric(0.4, 0.05, base_width=0.0, twist=1.0),
        LeafShape.parametric(0.4, 0.05, base_width=0.0, twist=1.0, undulation=0.003),
    ],
    ids=["closed-tip", "both-closed", "wavy-zero-width-base"],
)
def test_budgets_are_exact_and_meshes_valid(shape) -> None:
    nodes = _nodes(shape)
    for budget in (2, 3, 4, 7, 20, 41):
        faces = adaptive_faces(nodes, budget)
        assert len(faces) == budget
        _check_triangulation(nodes, faces)
    with pytest.raises(ParameterError, match="below the minimum"):
        adaptive_faces(nodes, 0)
    with pytest.raises(ParameterError, match="exceeds"):
        adaptive_faces(nodes, 10 * len(nodes.points))


def test_zero_width_base_with_waves_converges() -> None:
    # the margin wave does not vanish where the blade has no width: that row is kept open
    # (its points differ), so the error keeps falling with the budget
    leaf = LeafShape.parametric(0.3, 0.03, base_width=0.0, twist=2.0, undulation=0.001)
    assert _nodes(leaf).kind == 1  # tip closed, base open
    assert _nodes(LeafShape.parametric(0.3, 0.03, base_width=0.0)).kind == 3
    meshes = [adaptive_mesh(leaf, b, n_points=60) for b in (30, 120)]
    errs = [surface_error(leaf, m, n_s=301, n_u=11) for m in meshes]
    assert errs[1] < 0.5 * errs[0]


def test_open_ends_start_with_two_triangles() -> None:
    s, u = np.linspace(0, 1, 11), np.linspace(-0.5, 0.5, 5)
    pts = np.stack([*np.meshgrid(s, u, indexing="ij"), np.zeros((11, 5))], axis=-1)
    nodes = make_nodes(pts, s, u, np.ones(11))
    assert adaptive_faces(nodes, 2).shape == (2, 3)
    faces = adaptive_faces(nodes, 9)
    _check_triangulation(nodes, faces)
    # a plane is represented exactly by any triangulation
    assert point_triangle_distance(pts.reshape(-1, 3), pts.reshape(-1, 3)[faces]).max() < 1e-12


def test_twisted_undulated_maize_within_half_a_millimetre_at_200_triangles() -> None:
    maize = LeafShape.from_preset("maize")  # 30° twist, 4 mm margin waves every 6 cm
    mesh = reduced_mesh(maize, 200)
    assert mesh.n_faces == 200
    err = surface_error(maize, mesh, n_s=613, n_u=11)  # samples unlike the nodes
    strips = surface_error(maize, reduced_mesh(maize, 200, surface=False), n_s=613, n_u=11)
    assert err <= 0.5e-3 < 3e-3 < strips
    assert mesh.normals is not None and mesh.uv is not None
    assert np.allclose(np.linalg.norm(mesh.normals, axis=1), 1.0)
    assert set(mesh.face_ids) == {"plant", "leaf"}


def test_twisted_leaf_gets_the_better_of_strips_and_refinement() -> None:
    grass = LeafShape.from_preset("grass")  # 180° twist, no waves
    errs = {}
    for budget in (20, 80):
        ours = surface_error(grass, reduced_mesh(grass, budget))
        strips = surface_error(grass, reduced_mesh(grass, budget, surface=False))
        assert ours <= strips * 1.05
        errs[budget] = (ours, strips)
    assert errs[20][0] < 0.8 * errs[20][1]  # refinement wins on a coarse twisted blade
    assert errs[80][0] < errs[20][0]


def test_point_triangle_distance_matches_dense_sampling() -> None:
    rng = np.random.default_rng(5)
    tri = rng.normal(size=(6, 3, 3))
    pts = rng.normal(size=(40, 3)) * 2
    w = rng.dirichlet(np.ones(3), 20000)
    dense = np.einsum("kj,mjd->mkd", w, tri).reshape(-1, 3)
    ref = np.linalg.norm(pts[:, None] - dense[None], axis=-1).min(axis=1)
    got = point_triangle_distance(pts, tri)
    assert (got <= ref + 1e-12).all() and np.allclose(got, ref, atol=2e-2)
