"""Synthetic trees with ground truth: a Weber–Penn-style generator and a LiDAR simulator.

:func:`generate_tree` grows a tree level by level (trunk = order 0, its branches order 1, …)
in the spirit of Weber & Penn (1995, "Creation and rendering of realistic trees"): each
branch is a tapered, gently curving tube; children leave their parent at a *down angle*,
spiral around it with a phyllotactic *rotate angle*, and get a length from a crown *shape*
function of their position on the parent. The presets are sized like the procedural trees
of the thesis (Blender Sapling presets B4–B6: japanese maple NOB 286 / TBL 460.4 m, white
birch 291 / 599.07 m, quaking aspen 30 / 116.83 m) plus a conifer; the measured tip counts
and total lengths of our presets are tabulated in ``docs/tree_voxel.md``.

:func:`generate_stand` places several such trees on a jittered grid (a plot with truth
for the crown partition: ``tree_id`` per node).

:func:`simulate_scan` turns such a truth :class:`~biomorph.core.graph.BranchGraph` into a
terrestrial-LiDAR-like :class:`~biomorph.core.pointcloud.PointCloud` (see its docstring).

All lengths are metres, angles radians, Z up, the stem base at the origin.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numba
import numpy as np
from numpy.typing import NDArray

from biomorph.core.graph import BranchGraph
from biomorph.core.pointcloud import PointCloud
from biomorph.errors import InputError, ParameterError

__all__ = ["Level", "TreeParams", "PRESETS", "generate_stand", "generate_tree", "simulate_scan"]


@dataclass(frozen=True)
class Level:
    """Parameters of one branching level (children of the previous level).

    ``n``: children per parent branch of full length (scaled by the parent's relative
    length); ``length``: child length as a fraction of the parent's length (before the shape
    factor); ``down``: angle between parent and child direction (rad); ``down_var``: its
    random spread; ``rotate``: azimuth increment between successive children (rad);
    ``curve``: total upward bending along the branch (rad, negative bends down);
    ``curve_var``: random lateral bending (rad); ``radius``: child base radius as a fraction
    of the parent's local radius; ``start``: first attachment position on the parent (0..1);
    ``step``: node spacing (m).
    """

    n: float
    length: float
    down: float
    down_var: float = 0.15
    rotate: float = math.radians(137.5)
    curve: float = 0.3
    curve_var: float = 0.3
    radius: float = 0.6
    start: float = 0.1
    step: float = 0.06


@dataclass(frozen=True)
class TreeParams:
    """Whole-tree parameters: trunk ``height`` (m), trunk ``base_radius`` (m), ``base_size``
    (fraction of the trunk without branches), crown ``shape`` (``"conical"``,
    ``"spherical"``, ``"hemispherical"``, ``"cylindrical"``, ``"tapered_cylindrical"``,
    ``"flame"``), trunk ``curve_var`` (rad), ``tip_radius`` (m), trunk node ``step`` (m) and
    the branching ``levels``."""

    height: float = 8.0
    base_radius: float = 0.15
    base_size: float = 0.25
    shape: str = "spherical"
    curve_var: float = 0.1
    tip_radius: float = 0.004
    step: float = 0.1
    taper: float = 0.95
    levels: tuple[Level, ...] = field(default_factory=tuple)


PRESETS: dict[str, TreeParams] = {
    # japanese maple: short, wide, many thin twigs (thesis B4: NOB 286, TBL 460.4 m)
    "maple": TreeParams(
        height=9.0,
        base_radius=0.16,
        base_size=0.2,
        shape="hemispherical",
        curve_var=0.15,
        levels=(
            Level(
                n=12,
                length=0.82,
                down=math.radians(55),
                curve=0.35,
                radius=0.55,
                start=0.0,
                step=0.08,
            ),
            Level(
                n=7,
                length=0.66,
                down=math.radians(45),
                curve=0.2,
                radius=0.6,
                start=0.15,
                step=0.06,
            ),
            Level(
                n=5, length=0.6, down=math.radians(40), curve=0.1, radius=0.6, start=0.2, step=0.05
            ),
        ),
    ),
    # white birch: tall, slender, drooping fine branches (thesis B5: NOB 291, TBL 599.07 m)
    "birch": TreeParams(
        height=15.0,
        base_radius=0.17,
        base_size=0.3,
        shape="flame",
        curve_var=0.08,
        levels=(
            Level(
                n=30,
                length=0.42,
                down=math.radians(50),
                curve=0.2,
                radius=0.5,
                start=0.0,
                step=0.08,
            ),
            Level(
                n=14,
                length=0.75,
                down=math.radians(50),
                curve=-0.3,
                radius=0.55,
                start=0.15,
                step=0.06,
            ),
        ),
    ),
    # quaking aspen: tall straight stem, few long branches (thesis B6: NOB 30, TBL 116.83 m)
    "aspen": TreeParams(
        height=15.0,
        base_radius=0.18,
        base_size=0.35,
        shape="tapered_cylindrical",
        curve_var=0.06,
        levels=(
            Level(
                n=29,
                length=0.3,
                down=math.radians(45),
                curve=0.35,
                radius=0.45,
                start=0.0,
                step=0.08,
            ),
        ),
    ),
    # conifer: monopodial stem, whorls of near-horizontal branches, conical crown
    "conifer": TreeParams(
        height=12.0,
        base_radius=0.2,
        base_size=0.1,
        shape="conical",
        curve_var=0.03,
        levels=(
            Level(
                n=45,
                length=0.3,
                down=math.radians(80),
                down_var=0.1,
                rotate=math.radians(99.5),
                curve=0.25,
                curve_var=0.15,
                radius=0.35,
                start=0.0,
                step=0.07,
            ),
            Level(
                n=4, length=0.35, down=math.radians(55), curve=0.0, radius=0.6, start=0.2, step=0.05
            ),
        ),
    ),
}


def _shape_ratio(shape: str, r: NDArray[np.float64]) -> NDArray[np.float64]:
    """Weber–Penn crown shape factor; ``r`` = 1 at the crown base, 0 at the top."""
    if shape == "conical":
        return 0.2 + 0.8 * r
    if shape == "spherical":
        return 0.2 + 0.8 * np.sin(np.pi * r)
    if shape == "hemispherical":
        return 0.2 + 0.8 * np.sin(0.5 * np.pi * r)
    if shape == "cylindrical":
        return np.ones_like(r)
    if shape == "tapered_cylindrical":
        return 0.5 + 0.5 * r
    if shape == "flame":
        return np.where(r >= 0.3, (1 - r) / 0.7, r / 0.3).clip(0.1)
    raise ParameterError(
        f"unknown crown shape {shape!r}; expected conical, spherical, "
        "hemispherical, cylindrical, tapered_cylindrical or flame"
    )


def _perp(d: NDArray[np.float64]) -> NDArray[np.float64]:
    """A unit vector perpendicular to unit vector ``d``."""
    a = np.array([0.0, 0.0, 1.0]) if abs(d[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    p = np.cross(d, a)
    return p / np.linalg.norm(p)


def _rotate(
    v: NDArray[np.float64], axis: NDArray[np.float64], angle: NDArray[np.float64] | float
) -> NDArray[np.float64]:
    """Rodrigues rotation of vector(s) ``v`` about unit ``axis`` by ``angle`` (broadcast)."""
    angle = np.asarray(angle, dtype=float)[..., None]
    c, s = np.cos(angle), np.sin(angle)
    return v * c + np.cross(axis, v) * s + axis * float(axis @ v) * (1 - c)


def _branch_axis(
    start: NDArray[np.float64],
    d0: NDArray[np.float64],
    length: float,
    step: float,
    curve: float,
    curve_var: float,
    rng: np.random.Generator,
) -> NDArray[np.float64]:
    """Node positions (excluding ``start``) of a smoothly bending branch of given length."""
    nseg = max(2, int(math.ceil(length / step)))
    t = np.arange(nseg) / max(nseg - 1, 1)
    up = np.array([0.0, 0.0, 1.0])
    ax_up = np.cross(d0, up)
    nrm = np.linalg.norm(ax_up)
    ax_up = ax_up / nrm if nrm > 1e-6 else _perp(d0)
    # bending toward the vertical (phototropism / gravitropism) ...
    dirs = _rotate(d0, -ax_up, curve * t)
    # ... plus a random low-frequency lateral wobble
    ax_r = _perp(d0)
    ax_r = _rotate(ax_r, d0, rng.uniform(0, 2 * np.pi))
    phase = rng.uniform(0, 2 * np.pi)
    wob = curve_var * (np.sin(np.pi * t + phase) - np.sin(phase))
    dirs = _rotate_rows(dirs, ax_r, wob)
    seg = length / nseg
    return start + np.cumsum(dirs * seg, axis=0)


def _rotate_rows(
    v: NDArray[np.float64], axis: NDArray[np.float64], angle: NDArray[np.float64]
) -> NDArray[np.float64]:
    c, s = np.cos(angle)[:, None], np.sin(angle)[:, None]
    return v * c + np.cross(axis, v) * s + axis * (v @ axis)[:, None] * (1 - c)


def generate_tree(
    preset: str | TreeParams = "maple", seed: int = 0, **overrides: object
) -> BranchGraph:
    """Grow a synthetic tree and return its true skeleton.

    Parameters
    ----------
    preset : a key of :data:`PRESETS` (``maple``, ``birch``, ``aspen``, ``conifer``) or a
        :class:`TreeParams`.
    seed : random seed (same seed → same tree).
    overrides : fields of :class:`TreeParams` to replace (e.g. ``height=10``).

    Returns
    -------
    BranchGraph with ``radius`` (m, tapering along each branch), ``depth`` = branch order
    (0 = trunk), stem base at the origin, Z up, node spacing 5–10 cm.
    """
    if isinstance(preset, str):
        if preset not in PRESETS:
            raise ParameterError(
                f"unknown tree preset {preset!r}; expected one of {', '.join(sorted(PRESETS))}"
            )
        params = PRESETS[preset]
    else:
        params = preset
    if overrides:
        bad = set(overrides) - set(TreeParams.__dataclass_fields__)
        if bad:
            raise ParameterError(f"unknown tree parameter(s) {sorted(bad)}")
        params = replace(params, **overrides)  # type: ignore[arg-type]
    if params.height <= 0 or params.base_radius <= 0:
        raise ParameterError("tree height and base_radius must be > 0")
    rng = np.random.default_rng(seed)

    pos_chunks: list[NDArray] = []
    par_chunks: list[NDArray] = []
    rad_chunks: list[NDArray] = []
    dep_chunks: list[NDArray] = []
    n_total = 0

    def add_branch(
        start_idx: int,
        start: NDArray,
        d0: NDArray,
        length: float,
        r0: float,
        step: float,
        curve: float,
        curve_var: float,
        depth: int,
    ) -> tuple[int, int]:
        nonlocal n_total
        pts = _branch_axis(start, d0, length, step, curve, curve_var, rng)
        m = pts.shape[0]
        first = n_total
        parent = np.arange(first - 1, first + m - 1)
        parent[0] = start_idx
        s = np.arange(1, m + 1) / m
        r_tip = min(params.tip_radius, r0)
        rad = r0 + (r_tip - r0) * s**params.taper
        pos_chunks.append(pts)
        par_chunks.append(parent)
        rad_chunks.append(rad)
        dep_chunks.append(np.full(m, depth))
        n_total += m
        return first, m

    # trunk: a root node at the origin, then the stem
    pos_chunks.append(np.zeros((1, 3)))
    par_chunks.append(np.array([-1]))
    rad_chunks.append(np.array([params.base_radius]))
    dep_chunks.append(np.array([0]))
    n_total = 1
    up = np.array([0.0, 0.0, 1.0])
    first, m = add_branch(
        0, np.zeros(3), up, params.height, params.base_radius, params.step, 0.0, params.curve_var, 0
    )
    # (first node, node count, length, base fraction, parent-level index)
    branches = [(first, m, params.height, 0)]
    for lev_i, lev in enumerate(params.levels):
        new = []
        max_len = max(b[2] for b in branches)
        for bfirst, bm, blen, _ in branches:
            rel = blen / max_len
            n_child = int(round(lev.n * (0.25 + 0.75 * rel) if lev_i else lev.n))
            if n_child <= 0 or bm < 3:
                continue
            start = params.base_size if lev_i == 0 else lev.start
            tpos = (
                start
                + (1 - start) * (np.arange(n_child) + rng.uniform(0.2, 0.8, n_child)) / n_child
            )
            tpos = np.clip(tpos, 0, 0.97)
            node = bfirst + np.minimum((tpos * bm).astype(int), bm - 2)
            crown_r = (1 - tpos) / (1 - start) if lev_i == 0 else 1 - tpos
            ratio = (
                _shape_ratio(params.shape, np.clip(crown_r, 0, 1))
                if lev_i == 0
                else 0.4 + 0.6 * np.clip(crown_r, 0, 1)
            )
            az0 = rng.uniform(0, 2 * np.pi)
            for j in range(n_child):
                ni = int(node[j])
                pdir = _pos_at(pos_chunks, ni + 1) - _pos_at(pos_chunks, ni)
                pdir /= np.linalg.norm(pdir)
                down = lev.down + rng.normal(0, lev.down_var)
                p = _perp(pdir)
                d = _rotate(pdir, p, down)
                d = _rotate(d, pdir, az0 + j * lev.rotate + rng.normal(0, 0.2))
                d /= np.linalg.norm(d)
                clen = blen * lev.length * float(ratio[j]) * rng.uniform(0.85, 1.15)
                r_par = float(_rad_at(rad_chunks, ni))
                r0 = min(
                    max(
                        min(r_par * lev.radius * math.sqrt(clen / blen) * 1.2, 0.8 * r_par),
                        params.tip_radius * 1.5,
                    ),
                    r_par,
                )
                cf, cm = add_branch(
                    ni,
                    _pos_at(pos_chunks, ni),
                    d,
                    clen,
                    r0,
                    lev.step,
                    lev.curve,
                    lev.curve_var,
                    lev_i + 1,
                )
                new.append((cf, cm, clen, ni))
        branches = new
    pos = np.concatenate(pos_chunks)
    pos[:, 2] -= pos[:, 2].min()  # nothing below the ground
    return BranchGraph(
        pos,
        np.concatenate(par_chunks),
        radius=np.concatenate(rad_chunks),
        depth=np.concatenate(dep_chunks),
    )


def generate_stand(
    preset: str = "conifer",
    n_trees: int = 7,
    spacing: float = 2.5,
    seed: int = 0,
    *,
    height: float = 14.0,
    height_range: tuple[float, float] = (0.6, 1.15),
    branch_scale: float = 0.5,
    crown_base: float = 0.45,
) -> BranchGraph:
    """A plot of ``n_trees`` synthetic trees with truth: ``tree_id`` per node (tree ``i``
    stands ``i``-th nearest to the origin; tree 0 at the origin).

    Stems stand on a square grid of ``spacing`` (m) around the origin, jittered by a
    quarter spacing and kept at least 0.4 spacings apart. Each tree is ``preset`` grown
    with its own seed, a height drawn uniformly in ``height_range`` × ``height`` (a stand
    has dominant and suppressed trees), first-order branches ``branch_scale`` times the
    preset's length and a crown base at least ``crown_base`` of the height: trees grown
    close together self-prune and keep short crowns (a plantation's crown ratio is
    30–55 %). Crowns touch and interleave like a thinned pine plot's; scanned with
    :func:`simulate_scan` (``distance`` past the plot's edge), the neighbours occlude the
    upper stems, which is what a plot's crown partition has to survive."""
    if n_trees < 1:
        raise ParameterError(f"n_trees must be >= 1; got {n_trees}")
    if not spacing > 0:
        raise ParameterError(f"spacing must be > 0 (metres); got {spacing}")
    if not 0 < height_range[0] <= height_range[1]:
        raise ParameterError(f"height_range must be 0 < low <= high; got {height_range}")
    if preset not in PRESETS:
        raise ParameterError(
            f"unknown tree preset {preset!r}; expected one of {', '.join(sorted(PRESETS))}"
        )
    rng = np.random.default_rng(seed)
    k = int(np.ceil(np.sqrt(n_trees)))
    grid = (
        np.stack(np.meshgrid(np.arange(k), np.arange(k), indexing="ij"), -1).reshape(-1, 2)
        - (k - 1) / 2
    ) * spacing
    xy = grid[np.argsort(np.hypot(grid[:, 0], grid[:, 1]), kind="stable")][:n_trees]
    xy = xy + rng.normal(0.0, 0.25 * spacing, xy.shape)
    xy[0] = 0.0
    for a in range(n_trees):  # no two stems closer than 0.4 spacings
        for b in range(a):
            d = xy[a] - xy[b]
            dist = float(np.hypot(d[0], d[1]))
            if dist < 0.4 * spacing:
                xy[a] = xy[b] + d / max(dist, 1e-9) * 0.4 * spacing
    base = PRESETS[preset]
    first = base.levels[0] if base.levels else None
    levels = (
        (replace(first, length=first.length * branch_scale),) + tuple(base.levels[1:])
        if first is not None
        else ()
    )
    parts = []
    offset = 0
    for t in range(n_trees):
        h = float(rng.uniform(*height_range)) * height
        g = generate_tree(
            base,
            seed=seed * 1000 + t,
            height=h,
            base_size=max(base.base_size, crown_base),
            levels=levels,
        )
        par = g.parent.copy()
        par[par >= 0] += offset
        parts.append((g.position + np.r_[xy[t], 0.0], par, g.radius, g.depth, t))
        offset += g.n_nodes
    return BranchGraph(
        np.concatenate([p[0] for p in parts]),
        np.concatenate([p[1] for p in parts]),
        radius=np.concatenate([p[2] for p in parts]),
        depth=np.concatenate([p[3] for p in parts]),
        tree_id=np.concatenate([np.full(p[0].shape[0], p[4], dtype=np.int64) for p in parts]),
    )


def _flat_get(chunks: list[NDArray], i: int) -> NDArray:
    for c in chunks:
        if i < c.shape[0]:
            return c[i]
        i -= c.shape[0]
    raise IndexError(i)


def _pos_at(chunks: list[NDArray], i: int) -> NDArray:
    return np.array(_flat_get(chunks, i), dtype=float)


def _rad_at(chunks: list[NDArray], i: int) -> float:
    return float(_flat_get(chunks, i))


# ------------------------------------------------------------------------- LiDAR simulator
@numba.njit(cache=True, nogil=True, parallel=True)
def _visible(
    occ: NDArray[np.bool_],
    origin: NDArray[np.float64],
    cell: float,
    scanner: NDArray[np.float64],
    pts: NDArray[np.float64],
    skip: NDArray[np.float64],
) -> NDArray[np.bool_]:
    """Ray-march from each point toward the scanner through an occupancy grid.

    A point is hidden when an occupied cell lies on the ray farther than ``skip[i]`` metres
    from the point (the point's own tube surface is ignored within that distance).
    """
    n = pts.shape[0]
    out = np.ones(n, dtype=np.bool_)
    nx, ny, nz = occ.shape
    h = 0.5 * cell
    for i in numba.prange(n):  # every ray on its own: the same answer on any core count
        dx = scanner[0] - pts[i, 0]
        dy = scanner[1] - pts[i, 1]
        dz = scanner[2] - pts[i, 2]
        dist = math.sqrt(dx * dx + dy * dy + dz * dz)
        dx /= dist
        dy /= dist
        dz /= dist
        t = skip[i]
        while t < dist:
            x = pts[i, 0] + dx * t
            y = pts[i, 1] + dy * t
            z = pts[i, 2] + dz * t
            ix = int(math.floor((x - origin[0]) / cell))
            iy = int(math.floor((y - origin[1]) / cell))
            iz = int(math.floor((z - origin[2]) / cell))
            if 0 <= ix < nx and 0 <= iy < ny and 0 <= iz < nz:
                if occ[ix, iy, iz]:
                    out[i] = False
                    break
            elif iz >= nz:
                break
            t += h
    return out


def _surface_samples(
    p0: NDArray, p1: NDArray, r: NDArray, n: int, rng: np.random.Generator
) -> tuple[NDArray, NDArray, NDArray]:
    """``n`` area-uniform samples on the lateral surfaces of tubes (p0→p1, radius r).

    Returns points, outward unit normals and the segment index of each sample.
    """
    axis = p1 - p0
    length = np.linalg.norm(axis, axis=1)
    area = 2 * np.pi * r * length
    prob = area / area.sum()
    seg = rng.choice(axis.shape[0], size=n, p=prob)
    u = axis[seg] / length[seg, None]
    a = np.where(np.abs(u[:, 2:3]) < 0.9, np.array([[0.0, 0, 1]]), np.array([[1.0, 0, 0]]))
    e1 = np.cross(u, a)
    e1 /= np.linalg.norm(e1, axis=1)[:, None]
    e2 = np.cross(u, e1)
    phi = rng.uniform(0, 2 * np.pi, n)
    nrm = e1 * np.cos(phi)[:, None] + e2 * np.sin(phi)[:, None]
    t = rng.uniform(0, 1, n)
    pts = p0[seg] + axis[seg] * t[:, None] + nrm * r[seg, None]
    return pts, nrm, seg


#: a surface sample deeper than this share of another tube's radius inside that tube is
#: inside the wood (where a branch starts at its parent's axis, the inner side of a bend):
#: no scanner sees it. The 5 % keeps the shared surface of two consecutive tubes of one
#: axis, whose radii differ by the taper of one step
INSIDE_SHARE = 0.95


def _inside_other_tubes(
    pts: NDArray, seg: NDArray, p0: NDArray, p1: NDArray, r: NDArray
) -> NDArray[np.bool_]:
    """True for samples lying inside a tube other than their own (distance to its axis
    segment below :data:`INSIDE_SHARE` of its radius)."""
    from scipy.spatial import cKDTree

    from biomorph.tree.metrics import _segment_kernel
    from biomorph.tree.neighbours import ball_lists

    out = np.zeros(pts.shape[0], dtype=bool)
    if pts.shape[0] == 0:
        return out
    reach = 0.5 * np.linalg.norm(p1 - p0, axis=1) + r
    cnt, idx = ball_lists(cKDTree(pts), 0.5 * (p0 + p1), reach)
    k = np.repeat(np.arange(p0.shape[0]), cnt)
    other = seg[idx] != k
    idx, k = idx[other], k[other]
    ends = np.concatenate([p0, p1])  # segment k runs from ends[k] to ends[m + k]
    m = p0.shape[0]
    _, d = _segment_kernel(np.ascontiguousarray(pts[idx]), (m + k)[:, None], k[:, None], ends)
    d = d[:, 0]
    out[idx[d < INSIDE_SHARE * r[k]]] = True
    return out


def simulate_scan(
    truth: BranchGraph,
    *,
    n_points: int = 20000,
    scanners: int = 3,
    noise: float = 0.005,
    occlusion: bool = True,
    leaves: float = 0.0,
    ground: bool = True,
    seed: int = 0,
    range_density: bool = True,
    distance: float | None = None,
    ground_fraction: float = 0.2,
    occlusion_cell: float | None = None,
) -> PointCloud:
    """Simulate a terrestrial LiDAR scan of a synthetic tree.

    Model
    -----
    * ``scanners`` positions on a circle around the stem (radius ``distance``, default
      ``max(5, 0.8 * tree height)`` m) at 1.5 m height, evenly spaced in azimuth.
    * Candidate points are drawn area-uniformly on the tube surfaces (edge radius = mean
      of its two node radii); candidates inside another tube (a branch's base inside its
      parent, the inner side of a bend) are dropped. A scanner sees a candidate only if
      its surface faces it; with ``range_density`` it keeps it with a probability
      ∝ ``cos(incidence) / range²`` (the footprint density of a fixed angular step),
      otherwise uniformly.
    * ``occlusion``: rays from the point to the scanner are marched through an occupancy
      grid of the tube surfaces (cell ``occlusion_cell``, default 3 cm; thin twigs
      therefore occlude a little more than their true width) -- self-shadowing.
    * Range noise: Gaussian with std ``noise`` (m) along the scanner ray.
    * ``leaves``: fraction of extra points as leaf clutter, scattered (σ = 12 cm) around the
      tips of the highest branch orders; ``is_leaf`` marks them.
    * ``ground``: ``ground_fraction`` of the points on a gently undulating ground (±3 cm)
      around the tree (``is_ground``).

    Returns a :class:`PointCloud` with boolean attributes ``is_ground``, ``is_leaf`` and
    integer ``node`` (truth node the point was sampled from: the child node of its edge;
    nearest tip for leaves; -1 for ground). ``meta["scanners"]`` holds the scanner positions.
    """
    if n_points < 1:
        raise ParameterError(f"n_points must be >= 1; got {n_points}")
    if scanners < 1:
        raise ParameterError(f"scanners must be >= 1; got {scanners}")
    if noise < 0:
        raise ParameterError(f"noise must be >= 0 (metres); got {noise}")
    if not 0 <= leaves < 1:
        raise ParameterError(f"leaves must be a fraction in [0, 1); got {leaves}")
    if truth.radius is None:
        raise InputError("simulate_scan needs a truth graph with radii")
    rng = np.random.default_rng(seed)
    edges = truth.edges
    if edges.shape[0] == 0:
        raise InputError("simulate_scan needs a truth graph with at least one edge")
    p0 = truth.position[edges[:, 0]]
    p1 = truth.position[edges[:, 1]]
    r = 0.5 * (truth.radius[edges[:, 0]] + truth.radius[edges[:, 1]])
    ok = np.linalg.norm(p1 - p0, axis=1) > 1e-9
    p0, p1, r, edges = p0[ok], p1[ok], r[ok], edges[ok]
    lo = truth.position.min(axis=0) - truth.radius.max()
    hi = truth.position.max(axis=0) + truth.radius.max()
    height = float(hi[2] - lo[2])
    centre_xy = truth.position[truth.roots[0], :2]
    dist = distance if distance is not None else max(5.0, 0.8 * height)
    az = 2 * np.pi * np.arange(scanners) / scanners + rng.uniform(0, 2 * np.pi)
    scan_pos = np.stack(
        [
            centre_xy[0] + dist * np.cos(az),
            centre_xy[1] + dist * np.sin(az),
            np.full(scanners, 1.5),
        ],
        axis=1,
    )

    n_leaf = int(round(leaves * n_points))
    n_ground = int(round(ground_fraction * n_points)) if ground else 0
    n_wood = max(n_points - n_leaf - n_ground, 1)

    occ = None
    cell = occlusion_cell or 0.03
    if occlusion:
        area = 2 * np.pi * r * np.linalg.norm(p1 - p0, axis=1)
        n_occ = int(min(4e6, max(2e5, area.sum() / (0.4 * cell) ** 2)))
        opts, _, _ = _surface_samples(p0, p1, r, n_occ, rng)
        shape = np.ceil((hi - lo) / cell).astype(int) + 2
        occ = np.zeros(shape, dtype=bool)
        ijk = np.floor((opts - lo) / cell).astype(int)
        occ[ijk[:, 0], ijk[:, 1], ijk[:, 2]] = True

    xyz_list, node_list = [], []
    per_scanner = int(math.ceil(n_wood / scanners))
    for s in range(scanners):
        sp = scan_pos[s]
        m = per_scanner * 6
        pts, nrm, seg = _surface_samples(p0, p1, r, m, rng)
        v = sp - pts
        rng_d = np.linalg.norm(v, axis=1)
        v /= rng_d[:, None]
        cos = np.einsum("ij,ij->i", v, nrm)
        front = cos > 0.05
        pts, seg, v, rng_d, cos = pts[front], seg[front], v[front], rng_d[front], cos[front]
        # surfaces inside the wood (a branch's first centimetres inside its parent) are
        # never seen, occlusion or not
        out = ~_inside_other_tubes(pts, seg, p0, p1, r)
        pts, seg, v, rng_d, cos = pts[out], seg[out], v[out], rng_d[out], cos[out]
        if occ is not None and pts.shape[0]:
            skip = 1.5 * cell + 2 * r[seg] * (1 - cos) + 1e-3
            vis = _visible(occ, lo, cell, sp, pts, skip)
            pts, seg, v, rng_d, cos = pts[vis], seg[vis], v[vis], rng_d[vis], cos[vis]
        if pts.shape[0] == 0:
            continue
        w = cos / rng_d**2 if range_density else np.ones(pts.shape[0])
        k = min(per_scanner, pts.shape[0])
        pick = rng.choice(pts.shape[0], size=k, replace=False, p=w / w.sum())
        q = pts[pick] + v[pick] * rng.normal(0, noise, k)[:, None] if noise > 0 else pts[pick]
        xyz_list.append(q)
        node_list.append(edges[seg[pick], 1])
    if not xyz_list:
        raise InputError("simulate_scan: no tree surface visible from the scanners")
    wood = np.concatenate(xyz_list)
    wnode = np.concatenate(node_list)
    if wood.shape[0] > n_wood:
        keep = np.sort(rng.choice(wood.shape[0], n_wood, replace=False))
        wood, wnode = wood[keep], wnode[keep]

    parts = [wood]
    nodes = [wnode]
    is_leaf = [np.zeros(wood.shape[0], bool)]
    is_ground = [np.zeros(wood.shape[0], bool)]
    if n_leaf:
        tips = truth.leaves
        if truth.depth is not None:
            dmax = truth.depth[tips].max()
            sel = tips[truth.depth[tips] >= max(dmax - 1, 0)]
            tips = sel if sel.size else tips
        t = rng.choice(tips, n_leaf)
        lp = truth.position[t] + rng.normal(0, 0.12, (n_leaf, 3))
        parts.append(lp)
        nodes.append(t)
        is_leaf.append(np.ones(n_leaf, bool))
        is_ground.append(np.zeros(n_leaf, bool))
    if n_ground:
        half = 0.5 * max(hi[0] - lo[0], hi[1] - lo[1]) + 1.0
        gx = rng.uniform(-half, half, (n_ground * 2, 2)) + centre_xy
        rb = float(truth.radius[truth.roots[0]])
        gx = gx[np.linalg.norm(gx - centre_xy, axis=1) > rb][:n_ground]
        gz = (
            0.03 * np.sin(gx[:, 0] * 1.3) * np.cos(gx[:, 1] * 0.9)
            + rng.normal(0, noise, gx.shape[0])
            + float(truth.position[:, 2].min())
        )
        parts.append(np.column_stack([gx, gz]))
        nodes.append(np.full(gx.shape[0], -1))
        is_leaf.append(np.zeros(gx.shape[0], bool))
        is_ground.append(np.ones(gx.shape[0], bool))
    xyz = np.concatenate(parts)
    return PointCloud(
        xyz,
        attributes={
            "is_ground": np.concatenate(is_ground),
            "is_leaf": np.concatenate(is_leaf),
            "node": np.concatenate(nodes).astype(np.int64),
        },
        meta={"scanners": scan_pos.tolist()},
        source="synthetic scan",
    )
