"""Reference skeletons from other tools and agreement measures.

* :func:`read_qsm_csv` — a cylinder QSM as CSV (SimpleForest / rTwig columns ``ID, parentID,
  startX … endZ, radius, length, …``; TreeQSM-style ``start_x … axis_z, length, parent``
  as written by :func:`biomorph.tree.export.write_cylinders` also works) → BranchGraph
  whose nodes are the cylinder end points (radius = the cylinder's radius) plus one base
  node per root cylinder.
* :func:`read_treeqsm_mat` — TreeQSM's MATLAB ``OptQSM`` (``.mat``, its ``cylinder``
  struct: ``start``, ``axis``, ``length``, ``radius``, 1-based ``parent``, ``BranchOrder``)
  → the same kind of BranchGraph.
* :func:`read_reference` — a QSM CSV, a TreeQSM ``.mat`` or any graph ``bm.io.read_graph``
  reads (MTG, PLY),
  optionally shifted into the cloud's frame. plantscan3d's ``A3B4.mtg`` is the ``.asc``
  cloud minus its mean (see ``../shared/data/trees/README.md``): pass
  ``shift=mean(asc points)``.
* :func:`compare_to_reference` — tip count, total length, radius profile (radius against
  height, in bins) and skeleton F1 within a tolerance (``metrics.compare_to_truth``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from biomorph.core.graph import BranchGraph
from biomorph.errors import FormatError

__all__ = [
    "read_qsm_csv",
    "read_treeqsm_mat",
    "read_reference",
    "compare_to_reference",
    "radius_profile",
]

from biomorph.core.types import PathLike


def _columns(path: PathLike) -> tuple[list[str], NDArray[np.float64]]:
    p = Path(path)
    if not p.is_file():
        raise FormatError(path, "file does not exist")
    lines = p.read_text(encoding="utf-8", errors="replace").splitlines()
    if not lines:
        raise FormatError(path, "empty file; expected a header line and cylinder rows")
    header = [h.strip() for h in lines[0].split(",")]
    rows = []
    for i, line in enumerate(lines[1:], start=2):
        if not line.strip():
            continue
        parts = line.split(",")
        if len(parts) != len(header):
            raise FormatError(path, f"{len(parts)} values; expected {len(header)}", line=i)
        try:
            rows.append([float(x) for x in parts])
        except ValueError:
            raise FormatError(path, "non-numeric value; expected numbers", line=i) from None
    if not rows:
        raise FormatError(path, "no cylinder rows")
    data = np.asarray(rows)
    if not np.isfinite(data).all():
        raise FormatError(path, "NaN or inf in the table; expected finite numbers")
    return header, data


def read_qsm_csv(path: PathLike) -> BranchGraph:
    """Read a cylinder QSM CSV as a BranchGraph (metres; see the module doc)."""
    header, data = _columns(path)
    col = {h: i for i, h in enumerate(header)}

    def get(*names: str) -> NDArray | None:
        for nm in names:
            if nm in col:
                return data[:, col[nm]]
        return None

    ids = get("ID")
    parent_id = get("parentID", "parent")
    start = [get(f"start{a}", f"start_{a.lower()}") for a in "XYZ"]
    end = [get(f"end{a}") for a in "XYZ"]
    radius = get("radius")
    if ids is None or parent_id is None or radius is None or any(s is None for s in start):
        raise FormatError(
            path,
            "missing columns; expected ID, parentID (or parent), "
            "startX..startZ (or start_x..), radius",
        )
    start_xyz = np.column_stack(start)
    if any(e is None for e in end):
        axis = np.column_stack([get(f"axis_{a}") for a in "xyz"])
        length = get("length")
        end_xyz = start_xyz + axis * length[:, None]
    else:
        end_xyz = np.column_stack(end)
    m = ids.size
    order = np.argsort(ids, kind="stable")
    sid = ids[order]
    pos = np.searchsorted(sid, parent_id)
    pos = np.minimum(pos, m - 1)
    has_parent = sid[pos] == parent_id
    pidx = np.where(has_parent, order[pos], -1)
    roots = np.flatnonzero(pidx < 0)
    parent = np.where(pidx >= 0, pidx, m + np.searchsorted(roots, np.arange(m)))
    position = np.vstack([end_xyz, start_xyz[roots]])
    par = np.concatenate([parent, np.full(roots.size, -1)])
    rad = np.concatenate([radius, radius[roots]])
    depth = get("branchOrder", "BranchOrder")
    dep = None if depth is None else np.concatenate([depth, depth[roots]]).astype(np.int64)
    return BranchGraph(position, par, radius=rad, depth=dep)


def _cylinders_to_graph(start, axis, length, radius, parent, order) -> BranchGraph:
    """Cylinders (``parent`` 0-based, -1 = none) as a BranchGraph: a node at the end of
    every cylinder plus one at the start of every root cylinder, each with its cylinder's
    radius and branch order."""
    start = np.asarray(start, float).reshape(-1, 3)
    end = start + np.asarray(axis, float).reshape(-1, 3) * np.asarray(length, float)[:, None]
    parent = np.asarray(parent, np.int64)
    m = parent.size
    roots = np.flatnonzero(parent < 0)
    par = np.where(parent >= 0, parent, m + np.searchsorted(roots, np.arange(m)))
    rad = np.asarray(radius, float)
    dep = np.asarray(order, np.int64)
    return BranchGraph(
        np.vstack([end, start[roots]]),
        np.concatenate([par, np.full(roots.size, -1)]),
        radius=np.concatenate([rad, rad[roots]]),
        depth=np.concatenate([dep, dep[roots]]),
    )


def read_treeqsm_mat(path: PathLike) -> BranchGraph:
    """TreeQSM's ``OptQSM`` MATLAB file (v5, as TreeQSM and rTwig ship it) as a BranchGraph
    of its cylinders (metres)."""
    import scipy.io

    try:
        mat = scipy.io.loadmat(path, squeeze_me=True, struct_as_record=False)
    except (ValueError, OSError, TypeError) as exc:
        raise FormatError(path, f"not a readable MATLAB v5 file ({exc})") from None
    q = mat.get("OptQSM", mat.get("QSM"))
    cyl = getattr(q, "cylinder", None)
    need = ("start", "axis", "length", "radius", "parent")
    if cyl is None or any(not hasattr(cyl, k) for k in need):
        raise FormatError(
            path,
            "no OptQSM.cylinder with start, axis, length, radius, parent; expected a TreeQSM model",
        )
    order = getattr(cyl, "BranchOrder", np.zeros(np.size(cyl.radius)))
    return _cylinders_to_graph(
        cyl.start, cyl.axis, cyl.length, cyl.radius, np.asarray(cyl.parent, np.int64) - 1, order
    )


def read_reference(path: PathLike, shift: NDArray | None = None) -> BranchGraph:
    """A reference skeleton: ``.csv`` QSM, TreeQSM ``.mat`` or any ``bm.io.read_graph``
    format, plus ``shift`` (added to positions) to bring it into the cloud's frame."""
    suffix = Path(path).suffix.lower()
    if suffix == ".csv":
        g = read_qsm_csv(path)
    elif suffix == ".mat":
        g = read_treeqsm_mat(path)
    else:
        from biomorph.io import read_graph

        g = read_graph(path)
    if shift is not None:
        g = g.with_(position=g.position + np.asarray(shift, dtype=float))
    return g


def radius_profile(graph: BranchGraph, bins: NDArray[np.float64]) -> NDArray[np.float64]:
    """Length-weighted mean radius of the edges whose child lies in each height bin (m)."""
    if graph.radius is None:
        return np.full(bins.size - 1, np.nan)
    z = graph.position[:, 2]
    el = graph.edge_length
    idx = np.digitize(z, bins) - 1
    ok = (idx >= 0) & (idx < bins.size - 1) & (el > 0)
    num = np.bincount(idx[ok], weights=graph.radius[ok] * el[ok], minlength=bins.size - 1)
    den = np.bincount(idx[ok], weights=el[ok], minlength=bins.size - 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return num / den


def compare_to_reference(
    graph: BranchGraph, reference: BranchGraph, tolerance: float | None = None, n_bins: int = 10
) -> dict[str, Any]:
    """Agreement of a skeleton with a reference model in the same frame.

    Returns tips and total length of both (and their ratios), base radius of both, the
    radius profile over ``n_bins`` height bins (and the median relative difference),
    precision/recall/F1 within ``tolerance`` from :func:`biomorph.tree.metrics.compare_to_truth`
    and, where both carry radii, the wood volume (m³) of both in all and per diameter
    class (``classes``: label → [ours, reference]) and, where both carry branch orders,
    the longest trunk of each (m) — what issue 13 asks a model to agree on.
    """
    from biomorph.tree.metrics import compare_to_truth

    cmp = compare_to_truth(graph, reference, tolerance)
    z = np.concatenate([graph.position[:, 2], reference.position[:, 2]])
    bins = np.linspace(z.min(), z.max() + 1e-9, n_bins + 1)
    pa = radius_profile(graph, bins)
    pb = radius_profile(reference, bins)
    ok = np.isfinite(pa) & np.isfinite(pb) & (pb > 0)
    rel = np.abs(pa[ok] - pb[ok]) / pb[ok]

    def base_radius(g: BranchGraph) -> float | None:
        if g.radius is None or g.n_nodes == 0:
            return None
        r = g.roots[np.argmin(g.position[g.roots, 2])]
        return float(g.radius[r])

    tips, tips_ref = int(graph.leaves.size), int(reference.leaves.size)
    tl, tl_ref = graph.total_length, reference.total_length
    return {
        "tips": tips,
        "tips_reference": tips_ref,
        "tips_ratio": tips / max(tips_ref, 1),
        "length": tl,
        "length_reference": tl_ref,
        "length_ratio": tl / max(tl_ref, 1e-12),
        "base_radius": base_radius(graph),
        "base_radius_reference": base_radius(reference),
        "radius_profile": [None if not np.isfinite(v) else float(v) for v in pa],
        "radius_profile_reference": [None if not np.isfinite(v) else float(v) for v in pb],
        "radius_profile_error": float(np.median(rel)) if rel.size else None,
        "precision": cmp["precision"],
        "recall": cmp["recall"],
        "f1": cmp["f1"],
        "tolerance": cmp["tolerance"],
        "mean_distance": cmp.get("mean_distance"),
        **_wood_agreement(graph, reference),
    }


def _wood_agreement(graph: BranchGraph, reference: BranchGraph) -> dict[str, Any]:
    """Volume in all and per class, and trunk length, of a model and its reference (the
    keys present only where both models carry what they need)."""
    from biomorph.tree.metrics import tree_attributes, volume_by_class

    out: dict[str, Any] = {}
    if graph.radius is None or reference.radius is None:
        return out
    va, vb = volume_by_class(graph), volume_by_class(reference)
    ta = sum(v["volume"] for v in va.values())
    tb = sum(v["volume"] for v in vb.values())
    out.update(
        volume=ta,
        volume_reference=tb,
        volume_ratio=ta / tb if tb > 0 else None,
        classes={k: [va[k]["volume"], vb[k]["volume"]] for k in va},
    )
    if graph.depth is not None and reference.depth is not None:
        la = max((a["trunk_length"] for a in tree_attributes(graph)), default=0.0)
        lb = max((a["trunk_length"] for a in tree_attributes(reference)), default=0.0)
        out.update(
            trunk_length=la,
            trunk_length_reference=lb,
            trunk_length_ratio=la / lb if lb > 0 else None,
        )
    return out
