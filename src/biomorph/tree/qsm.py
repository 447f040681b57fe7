"""TreeQSM-style tables of a skeleton: cylinders, branches and tree attributes.

Column order and units follow TreeQSM (Raumonen et al. 2013; ``save_model_text``, whose
cylinder text file the Lignum QSMreader documents column by column), so scripts written
for TreeQSM's outputs read ours by column index:

``cylinder`` (one per skeleton edge parent → child, rows in topological order; the row
number, 1-based, is the cylinder's id):
    ``radius`` (m), ``length`` (m), ``start_x/y/z`` (m), ``axis_x/y/z`` (unit),
    ``parent`` (row of the cylinder ending at the start, 0 at a tree base),
    ``extension`` (row of the cylinder continuing this one in its branch, 0 if none),
    ``branch`` (1-based branch id), ``BranchOrder`` (0 = trunk), ``PositionInBranch``
    (1-based), ``added`` (1 where the radius is the taper model's because no reliable
    circle fit — nor its run's cylinder, the graph method's default ``--run-cylinders`` —
    measured it; TreeQSM marks gap-filling cylinders so), ``mad`` (mean
    absolute residual of the circle fit, m), ``SurfCov`` (angular coverage of the fit,
    0–1), ``UnmodRadius`` (the fitted circle radius before the taper model, m);
    then biomorph's ``ID`` (= row) and ``tree_id``.
``branch`` (one per branch = segment of constant order):
    ``order``, ``parent`` (branch id, 0 for a trunk), ``diameter`` (m, of the first
    cylinder), ``volume`` (litres, as TreeQSM), ``area`` (m², lateral), ``length`` (m),
    ``angle`` (degrees between the branch's first cylinder and its parent cylinder),
    ``height`` (m above the tree base where it starts), ``azimuth`` and ``zenith``
    (degrees, of the branch's first cylinder); then ``tree_id``.
``treedata`` (one per tree): ``TotalVolume``, ``TrunkVolume``, ``BranchVolume`` (litres),
    ``TreeHeight``, ``TrunkLength``, ``BranchLength``, ``TotalLength`` (m),
    ``NumberBranches`` (order-1 branches, TreeQSM's count), ``MaxBranchOrder``,
    ``TrunkArea``, ``BranchArea``, ``TotalArea`` (m²), ``DBHqsm`` (m, the taper model's),
    ``DBHcyl`` (m, the stem's circles at 1.0–1.6 m,
    :func:`biomorph.tree.radius.breast_height_fits`; TreeQSM's cylinder fitted at 1.1–1.5
    m; empty without one), ``CrownDiamAve`` (m), ``CrownBaseHeight``, ``CrownLength``
    (m), ``CrownRatio``; then ``tree_id`` and
    ``MeasuredStem`` (1: a tree standing on a stem the scan measured and reaching breast
    height, 0: a fragment — understorey, stump, piece of crown;
    :func:`biomorph.tree.metrics.tree_kinds`), and ``location_x/_y/_z`` (m, the base of
    the trunk: the tree's lowest root, in the graph's frame — TreeQSM's
    ``treedata.location``), so the trees of a plot or a batch form an inventory.

Cylinder volumes follow :func:`biomorph.tree.metrics.edge_volumes` (frusta inside a branch,
the branch's own radius where it leaves its parent).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from biomorph.core.graph import BranchGraph

__all__ = [
    "CYLINDER_COLUMNS",
    "BRANCH_COLUMNS",
    "TREEDATA_COLUMNS",
    "cylinder_table",
    "branch_table",
    "treedata_table",
]

CYLINDER_COLUMNS = (
    "radius",
    "length",
    "start_x",
    "start_y",
    "start_z",
    "axis_x",
    "axis_y",
    "axis_z",
    "parent",
    "extension",
    "branch",
    "BranchOrder",
    "PositionInBranch",
    "added",
    "mad",
    "SurfCov",
    "UnmodRadius",
    "ID",
    "tree_id",
)
BRANCH_COLUMNS = (
    "order",
    "parent",
    "diameter",
    "volume",
    "area",
    "length",
    "angle",
    "height",
    "azimuth",
    "zenith",
    "tree_id",
)
TREEDATA_COLUMNS = (
    "TotalVolume",
    "TrunkVolume",
    "BranchVolume",
    "TreeHeight",
    "TrunkLength",
    "BranchLength",
    "TotalLength",
    "NumberBranches",
    "MaxBranchOrder",
    "TrunkArea",
    "BranchArea",
    "TotalArea",
    "DBHqsm",
    "DBHcyl",
    "CrownDiamAve",
    "CrownBaseHeight",
    "CrownLength",
    "CrownRatio",
    "tree_id",
    "MeasuredStem",
    "location_x",
    "location_y",
    "location_z",
)
#: integer columns of the three tables (written without decimals)
INTEGER_COLUMNS = {
    "parent",
    "extension",
    "branch",
    "BranchOrder",
    "PositionInBranch",
    "added",
    "ID",
    "tree_id",
    "order",
    "NumberBranches",
    "MaxBranchOrder",
    "MeasuredStem",
}


def cylinder_table(
    graph: BranchGraph,
    segment: NDArray[np.int64] | None = None,
    quality: dict[str, NDArray] | None = None,
) -> dict[str, NDArray]:
    """TreeQSM cylinder columns (module doc). ``quality``: per-node ``reliable``,
    ``mad``, ``coverage``, ``fitted_radius`` of the radius fit (zeros / the radius when
    absent)."""
    from biomorph.tree.order import branch_order, continuation_from_segments, segments

    par = graph.parent
    ch = graph.order[par[graph.order] >= 0]  # children in topological order
    m = ch.size
    cid = np.zeros(graph.n_nodes, dtype=np.int64)  # 1-based cylinder ending at each node
    cid[ch] = np.arange(1, m + 1)
    start = graph.position[par[ch]]
    vec = graph.position[ch] - start
    length = np.linalg.norm(vec, axis=1)
    axis = vec / np.maximum(length, 1e-300)[:, None]
    radius = graph.radius[ch] if graph.radius is not None else np.zeros(m)
    seg = segments(graph) if segment is None else np.asarray(segment)
    depth = graph.depth if graph.depth is not None else branch_order(graph)
    cont = continuation_from_segments(graph, seg)
    extension = np.where(cont[ch] >= 0, cid[np.maximum(cont[ch], 0)], 0)
    _, seg_rank = np.unique(seg, return_inverse=True)
    seg_rank = seg_rank.reshape(-1)
    s = seg_rank[ch]
    pib = np.zeros(m, dtype=np.int64)
    order_in = np.argsort(s, kind="stable")  # topological order kept within a branch
    counts = np.bincount(s, minlength=seg_rank.max() + 1 if seg_rank.size else 0)
    first = np.concatenate([[0], np.cumsum(counts)])[:-1]
    pib[order_in] = np.arange(m) - np.repeat(first, counts)[np.arange(m)] + 1
    q = quality or {}
    reliable = np.asarray(q.get("reliable", np.ones(graph.n_nodes, bool)))[ch]
    if "segment" in q:  # a run's cylinder measured the section too
        reliable = reliable | np.asarray(q["segment"])[ch]
    unmod = np.asarray(
        q.get(
            "fitted_radius", graph.radius if graph.radius is not None else np.zeros(graph.n_nodes)
        )
    )[ch]
    unmod = np.where(unmod > 0, unmod, radius)
    return {
        "radius": radius,
        "length": length,
        "start_x": start[:, 0],
        "start_y": start[:, 1],
        "start_z": start[:, 2],
        "axis_x": axis[:, 0],
        "axis_y": axis[:, 1],
        "axis_z": axis[:, 2],
        "parent": cid[par[ch]],
        "extension": extension,
        "branch": s + 1,
        "BranchOrder": depth[ch],
        "PositionInBranch": pib,
        "added": (~reliable).astype(np.int64),
        "mad": np.asarray(q.get("mad", np.zeros(graph.n_nodes)))[ch],
        "SurfCov": np.asarray(q.get("coverage", np.zeros(graph.n_nodes)))[ch],
        "UnmodRadius": unmod,
        "ID": np.arange(1, m + 1),
        "tree_id": np.asarray(graph.trees)[ch],
    }


def _cylinder_volume_area(graph: BranchGraph, cyl: dict[str, NDArray]) -> tuple[NDArray, NDArray]:
    from biomorph.tree.metrics import edge_volumes

    child, length, diam, vol = edge_volumes(graph)
    # edge_volumes is indexed by child node; map to the table's rows (topological order)
    par = graph.parent
    ch = graph.order[par[graph.order] >= 0]
    row_of = np.zeros(graph.n_nodes, dtype=np.int64)
    row_of[ch] = np.arange(ch.size)
    v = np.zeros(ch.size)
    a = np.zeros(ch.size)
    v[row_of[child]] = vol
    a[row_of[child]] = np.pi * diam * length  # lateral area, mean diameter
    return v, a


def branch_table(graph: BranchGraph, cyl: dict[str, NDArray]) -> dict[str, NDArray]:
    """TreeQSM branch columns (module doc) from a :func:`cylinder_table`."""
    vol, area = _cylinder_volume_area(graph, cyl)
    b = cyl["branch"] - 1
    nb = int(b.max()) + 1 if b.size else 0
    first = np.full(nb, -1, dtype=np.int64)
    firsts = np.flatnonzero(cyl["PositionInBranch"] == 1)
    first[b[firsts]] = firsts
    axis = np.column_stack([cyl["axis_x"], cyl["axis_y"], cyl["axis_z"]])
    f = np.maximum(first, 0)
    pc = cyl["parent"][f] - 1  # parent cylinder row (-1 at a base)
    parent_branch = np.where(pc >= 0, cyl["branch"][np.maximum(pc, 0)], 0)
    pax = np.where((pc >= 0)[:, None], axis[np.maximum(pc, 0)], np.array([0.0, 0.0, 1.0]))
    cosang = np.clip(np.einsum("ij,ij->i", axis[f], pax), -1, 1)
    # tree base height per tree: lowest cylinder start
    tid = cyl["tree_id"]
    _, tix = np.unique(tid, return_inverse=True)
    base = np.full(tix.max() + 1 if tix.size else 0, np.inf)
    np.minimum.at(base, tix, cyl["start_z"])
    return {
        "order": cyl["BranchOrder"][f],
        "parent": parent_branch,
        "diameter": 2 * cyl["radius"][f],
        "volume": 1000 * np.bincount(b, weights=vol, minlength=nb),
        "area": np.bincount(b, weights=area, minlength=nb),
        "length": np.bincount(b, weights=cyl["length"], minlength=nb),
        "angle": np.where(pc >= 0, np.degrees(np.arccos(cosang)), 0.0),
        "height": cyl["start_z"][f] - base[tix[f]],
        "azimuth": np.degrees(np.arctan2(axis[f, 1], axis[f, 0])),
        "zenith": np.degrees(np.arccos(np.clip(axis[f, 2], -1, 1))),
        "tree_id": tid[f],
    }


def _or_nan(v: float | None) -> float:
    return float("nan") if v is None else float(v)


def treedata_table(
    graph: BranchGraph,
    cyl: dict[str, NDArray],
    quality: dict[str, NDArray] | None = None,
    dbh_fit: dict[int, float | None] | None = None,
) -> dict[str, NDArray]:
    """TreeQSM tree attributes per tree (module doc); ``quality``: the per-node fit
    quality (``reliable``) that tells a measured stem from a fragment; ``dbh_fit``: the
    stem circles' DBH per tree label (``DBHcyl``)."""
    from biomorph.tree.metrics import tree_attributes, tree_kinds

    _, area = _cylinder_volume_area(graph, cyl)
    attrs = tree_attributes(graph)
    kinds = tree_kinds(
        graph,
        None if quality is None else quality.get("reliable"),
        {int(a["tree"]): float(a["height"]) for a in attrs},
    )
    out: dict[str, list] = {c: [] for c in TREEDATA_COLUMNS}
    labels = graph.trees
    roots = graph.roots
    for a in attrs:
        own = roots[labels[roots] == a["tree"]]
        base = graph.position[own[np.argmin(graph.position[own, 2])]] if own.size else [np.nan] * 3
        m = cyl["tree_id"] == a["tree"]
        trunk = m & (cyl["BranchOrder"] == 0)
        row = {
            "TotalVolume": 1000 * a["total_volume"],
            "TrunkVolume": 1000 * a["trunk_volume"],
            "BranchVolume": 1000 * a["branch_volume"],
            "TreeHeight": a["height"],
            "TrunkLength": a["trunk_length"],
            "BranchLength": a["branch_length"],
            "TotalLength": a["total_length"],
            "NumberBranches": a["branches_order1"],
            "MaxBranchOrder": a["max_order"],
            "TrunkArea": float(area[trunk].sum()),
            "BranchArea": float(area[m & ~trunk].sum()),
            "TotalArea": float(area[m].sum()),
            "DBHqsm": a["dbh"],
            "DBHcyl": _or_nan((dbh_fit or {}).get(int(a["tree"]))),
            "CrownDiamAve": a["crown_diameter"],
            "CrownBaseHeight": a["crown_base_height"],
            "CrownLength": a["crown_length"],
            "CrownRatio": a["crown_length"] / a["height"] if a["height"] else np.nan,
            "tree_id": a["tree"],
            "MeasuredStem": int(kinds.get(int(a["tree"])) == "tree"),
            "location_x": float(base[0]),
            "location_y": float(base[1]),
            "location_z": float(base[2]),
        }
        for c in TREEDATA_COLUMNS:
            out[c].append(row[c])
    return {c: np.asarray(v) for c, v in out.items()}
