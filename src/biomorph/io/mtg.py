"""MTG (multiscale tree graph, OpenAlea / plantscan3d) FORM-A files with ``XX YY ZZ radius``.

Reading
-------
The ``MTG :`` section is a table whose first row is ``ENTITY-CODE`` followed by tab
columns up to the feature names (``XX YY ZZ radius`` …). In each entity row:

* the column of the entity code is the number of leading tabs;
* a code is a chain of ``<relation><label>`` steps, relation ``/`` (decomposition: first
  component of a complex), ``<`` (successor) or ``+`` (branch), label = class symbol + optional
  index (``N``, ``P1``, ``U12``); several steps on one row (``/P1/N1``) chain entities;
* a code starting with ``^`` refers to the last entity written in the same column; without
  ``^`` it refers to the last entity of the column to the left (column 0: the scene);
* feature values sit in the columns named by the header, after the code columns.

Entities carrying coordinates (``XX YY ZZ``) become graph nodes. A node's parent is the
entity its ``<``/``+`` step refers to; the first component (``/``) of a complex is a root,
unless the complex itself is a branch or successor of another complex, in which case the
parent is the last node component of that complex (this rule covers the usual plantscan3d
and OpenAlea exports; MTGs with explicit cross-scale topology are read the same way).
``+`` increases the branch order (``BranchGraph.depth``); ``<`` and ``/`` keep it.
``radius`` (metres) is kept when present; an empty radius cell (plantscan3d leaves some
empty) takes the nearest ancestor's radius, and the radius is dropped when empty everywhere.

Writing produces one plant ``/P1`` per tree with ``^/N`` root, ``^<N`` continuation and
``+N`` lateral rows; the continuation is the child with the same branch order
(``depth``) when the graph has orders (none if no child has it), else the child with the
largest subtree length, so orders round-trip.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from biomorph.core.graph import BranchGraph
from biomorph.core.types import PathLike
from biomorph.errors import FormatError, InputError
from biomorph.io.atomic import write_text

_STEP = re.compile(r"([/<+])([A-Za-z$])(\d*)")


def _fail(path: PathLike, msg: str, line: int | None = None) -> FormatError:
    return FormatError(path, msg, line=line)


def read_graph(path: PathLike, missing_radius: str = "inherit") -> BranchGraph:
    """Read the nodes carrying ``XX YY ZZ`` of an MTG file as a :class:`BranchGraph`.

    ``missing_radius``: what to do with a node row whose ``radius`` cell is empty while
    other rows have one. ``"inherit"`` (default) keeps the node and gives it the nearest
    ancestor's radius; ``"skip"`` ignores such rows entirely, as if they were not in the
    file (later rows then refer to the previous entity of that column). ``"skip"`` reproduces
    the figures quoted for ``plantscan3d_A3B4.mtg`` in the shared data README (589 nodes,
    136 tips, 31.23 m); ``"inherit"`` reads all 610 node rows of that file.
    """
    if missing_radius not in ("inherit", "skip"):
        raise InputError(f"missing_radius={missing_radius!r}; expected 'inherit' or 'skip'")
    data = Path(path).read_bytes()
    if not data.strip():
        raise _fail(path, "file is empty; expected an MTG (CODE: FORM-A ... MTG :)")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        try:
            text = data.decode("latin-1")
        except UnicodeDecodeError:  # pragma: no cover - latin-1 decodes everything
            raise _fail(path, "not text", line=data.count(b"\n", 0, exc.start) + 1) from None
    lines = text.splitlines()
    start = None
    for k, ln in enumerate(lines):
        if re.match(r"^\s*MTG\s*:", ln):
            start = k
            break
    if start is None:
        raise _fail(path, "has no 'MTG :' section; expected an MTG FORM-A file")
    hdr_idx = start + 1
    while hdr_idx < len(lines) and not lines[hdr_idx].strip():
        hdr_idx += 1
    if hdr_idx >= len(lines) or not lines[hdr_idx].strip().startswith("ENTITY-CODE"):
        raise _fail(
            path,
            "expected the 'ENTITY-CODE' header row after 'MTG :'",
            line=min(hdr_idx, len(lines)) + 1,
        )
    header = lines[hdr_idx].rstrip("\r\n").split("\t")
    feat_cols = {name.strip(): j for j, name in enumerate(header) if j > 0 and name.strip()}
    if not feat_cols:
        raise _fail(
            path, "header row names no features; expected XX YY ZZ [radius]", line=hdr_idx + 1
        )
    first_feat = min(feat_cols.values())
    missing = [c for c in ("XX", "YY", "ZZ") if c not in feat_cols]
    if missing:
        raise _fail(
            path,
            f"features {', '.join(missing)} missing; expected XX YY ZZ columns",
            line=hdr_idx + 1,
        )

    xx_col = feat_cols["XX"]
    r_col = feat_cols.get("radius", -1)
    skip_rows = missing_radius == "skip" and r_col >= 0
    # entity tables (python loop: MTG files are small; 10^5 rows parse in ~0.3 s)
    sym: list[str] = []
    ent_parent: list[int] = []  # entity referred to by the step
    ent_rel: list[str] = []
    ent_complex: list[int] = []  # complex (for '/' steps): the decomposed entity
    feats: list[list[str]] = []
    ent_line: list[int] = []
    last_in_col: dict[int, int] = {}
    for k in range(hdr_idx + 1, len(lines)):
        raw = lines[k]
        if not raw.strip() or raw.lstrip().startswith("#"):
            continue
        cells = raw.rstrip("\r\n").split("\t")
        if (
            skip_rows
            and len(cells) > xx_col
            and cells[xx_col].strip()
            and (len(cells) <= r_col or not cells[r_col].strip())
        ):
            continue
        col = len(raw) - len(raw.lstrip("\t"))
        code = cells[col].strip() if col < len(cells) else ""
        if not code:
            raise _fail(path, "row has no entity code", line=k + 1)
        if col >= first_feat:
            raise _fail(
                path,
                f"entity code in column {col}, past the first feature column {first_feat}",
                line=k + 1,
            )
        pos = 0
        if code.startswith("^"):
            ref = last_in_col.get(col)
            if ref is None:
                raise _fail(
                    path, f"'{code}' continues column {col} but no entity is there yet", line=k + 1
                )
            pos = 1
        else:
            ref = -1 if col == 0 else last_in_col.get(col - 1)
            if ref is None:
                raise _fail(
                    path, f"'{code}' refers to column {col - 1} but no entity is there", line=k + 1
                )
        steps = _STEP.findall(code[pos:])
        if not steps or "".join(a + b + c for a, b, c in steps) != code[pos:]:
            raise _fail(
                path,
                f"entity code {code!r} is malformed; expected e.g. '^<N', '+N', '/P1'",
                line=k + 1,
            )
        for rel, symbol, _idx in steps:
            sym.append(symbol)
            ent_parent.append(ref)
            ent_rel.append(rel)
            ent_complex.append(ref if rel == "/" else -1)
            feats.append([])
            ent_line.append(k + 1)
            ref = len(sym) - 1
        feats[-1] = cells
        last_in_col[col] = ref
    if not sym:
        raise _fail(path, "MTG section holds no entities", line=hdr_idx + 1)

    n_ent = len(sym)

    def value(cells: list[str], name: str, line: int) -> float:
        j = feat_cols.get(name)
        if j is None or j >= len(cells) or not cells[j].strip():
            return np.nan
        tok = cells[j].strip()
        try:
            return float(tok)
        except ValueError:
            raise _fail(
                path, f"feature {name} holds {tok[:30]!r}; expected a number", line=line
            ) from None

    xyzr = np.full((n_ent, 4), np.nan)
    for e in range(n_ent):
        if feats[e]:
            for j, name in enumerate(("XX", "YY", "ZZ", "radius")):
                xyzr[e, j] = value(feats[e], name, ent_line[e])
    has_xyz = np.isfinite(xyzr[:, :3]).any(axis=1)
    partial = has_xyz & ~np.isfinite(xyzr[:, :3]).all(axis=1)
    if partial.any():
        e = int(np.flatnonzero(partial)[0])
        raise _fail(
            path,
            "node has only some of XX YY ZZ or a NaN/inf; expected all three finite",
            line=ent_line[e],
        )
    if not has_xyz.any():
        raise _fail(path, "no entity carries XX YY ZZ coordinates; expected skeleton nodes")
    bad_r = has_xyz & np.isinf(xyzr[:, 3])
    if bad_r.any():
        raise _fail(
            path,
            "radius is inf; expected a finite number",
            line=ent_line[int(np.flatnonzero(bad_r)[0])],
        )

    # topology at node level
    node_of = np.full(n_ent, -1, dtype=np.int64)
    node_of[has_xyz] = np.arange(int(has_xyz.sum()))
    last_node_component: dict[int, int] = {}  # complex entity -> last node inside it
    complex_of = np.full(n_ent, -1, dtype=np.int64)
    parent = np.full(int(has_xyz.sum()), -1, dtype=np.int64)
    order = np.zeros(int(has_xyz.sum()), dtype=np.int64)
    ent_order = np.zeros(n_ent, dtype=np.int64)
    for e in range(n_ent):
        ref = ent_parent[e]
        rel = ent_rel[e]
        if rel == "/":
            complex_of[e] = ref
        elif ref >= 0:
            complex_of[e] = complex_of[ref]
        ent_order[e] = (ent_order[ref] if ref >= 0 else 0) + (1 if rel == "+" else 0)
        if not has_xyz[e]:
            continue
        i = node_of[e]
        if rel in "<+" and ref >= 0 and has_xyz[ref]:
            parent[i] = node_of[ref]
        elif rel == "/" and ref >= 0:
            # first node of a complex: attach to the complex's parent complex's last node
            pc = ent_parent[ref] if ent_rel[ref] in "<+" else -1
            if pc >= 0 and pc in last_node_component:
                parent[i] = last_node_component[pc]
        elif ref >= 0 and not has_xyz[ref]:
            raise _fail(
                path, f"node refers by '{rel}' to an entity without coordinates", line=ent_line[e]
            )
        order[i] = ent_order[e]
        c = complex_of[e]
        if c >= 0:
            last_node_component[int(c)] = int(i)
    radius = xyzr[has_xyz, 3]
    rad = None if np.isnan(radius).all() else _fill_missing_radius(parent, radius)
    try:
        return BranchGraph(xyzr[has_xyz, :3], parent, radius=rad, depth=order)
    except InputError as exc:
        raise _fail(path, str(exc)) from None


def _fill_missing_radius(
    parent: NDArray[np.int64], radius: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Empty radius cells take the nearest ancestor's radius (roots: the smallest known)."""
    missing = np.isnan(radius)
    if not missing.any():
        return radius
    from biomorph.core import treeops

    out = radius.copy()
    order = treeops.topological_order(parent)
    fallback = float(np.nanmin(radius))
    miss_in_order = order[missing[order]]
    # parents come first in `order`, so one ordered pass fills chains of missing values
    for i in miss_in_order.tolist():
        p = parent[i]
        out[i] = out[p] if p >= 0 and not np.isnan(out[p]) else fallback
    return out


def _continuation_child(graph: BranchGraph) -> NDArray[np.int64]:
    """Per node, the child continuing its axis (``<``), -1 if none."""
    n = graph.n_nodes
    cont = np.full(n, -1, dtype=np.int64)
    child = np.flatnonzero(graph.parent >= 0)
    if child.size == 0:
        return cont
    par = graph.parent[child]
    score = graph.subtree_sum(graph.edge_length)[child]
    if graph.depth is not None:  # only a child of the same order continues the axis
        keep = graph.depth[child] == graph.depth[par]
        child, par, score = child[keep], par[keep], score[keep]
    # best child per parent: sort by (parent, -score), take the first of each parent
    idx = np.lexsort((-score, par))
    first = np.r_[True, par[idx][1:] != par[idx][:-1]]
    cont[par[idx][first]] = child[idx][first]
    return cont


def write_graph(path: PathLike, graph: BranchGraph) -> Path:
    """Write a :class:`BranchGraph` as MTG FORM-A (one ``/P`` per tree; ``XX YY ZZ radius``)."""
    if not isinstance(graph, BranchGraph):
        graph = getattr(graph, "graph", graph)
    if not isinstance(graph, BranchGraph):
        raise InputError(f"{os.fspath(path)}: expected a BranchGraph, got {type(graph).__name__}")
    if graph.n_nodes == 0:
        raise InputError(f"{os.fspath(path)}: graph has no nodes; nothing to write")
    cont = _continuation_child(graph)
    indptr, indices = graph.children_csr
    rows: list[tuple[int, str, int]] = []  # (column, code, node or -1)
    for t, root in enumerate(graph.roots):
        rows.append((0, f"/P{t + 1}", -1))
        stack: list[tuple[int, int, str]] = [(int(root), 0, "^/N")]
        while stack:
            node, col, code = stack.pop()
            rows.append((col, code, node))
            c = int(cont[node])
            if c >= 0:
                stack.append((c, col, "^<N"))
            kids = indices[indptr[node] : indptr[node + 1]]
            for k in kids[::-1]:
                if k != c:
                    stack.append((int(k), col + 1, "+N"))
    ncol = max(col for col, _, _ in rows) + 1
    feats = ["XX", "YY", "ZZ"] + (["radius"] if graph.radius is not None else [])
    out = (
        [
            "CODE :\tFORM-A",
            "",
            "CLASSES :",
            "SYMBOL\tSCALE\tDECOMPOSITION\tINDEXATION\tDEFINITION",
            "$\t0\tFREE\tFREE\tIMPLICIT",
            "P\t1\tFREE\tFREE\tEXPLICIT",
            "N\t2\tFREE\tFREE\tEXPLICIT",
            "",
            "DESCRIPTION :",
            "LEFT\tRIGHT\tRELTYPE\tMAX",
            "P\tP\t<\t?",
            "P\tP\t+\t?",
            "N\tN\t<\t?",
            "N\tN\t+\t?",
            "",
            "FEATURES :",
            "NAME\tTYPE",
        ]
        + [f"{f}\tREAL" for f in feats]
        + ["", "MTG :"]
    )
    out.append("ENTITY-CODE" + "\t" * ncol + "\t".join(feats))
    pos = graph.position
    rad = graph.radius
    for col, code, node in rows:
        prefix = "\t" * col + code + "\t" * (ncol - col)
        if node < 0:
            out.append(prefix + "\t" * (len(feats) - 1))
            continue
        vals = [repr(float(v)) for v in pos[node]]
        if rad is not None:
            vals.append(repr(float(rad[node])))
        out.append(prefix + "\t".join(vals))
    return write_text(path, "\n".join(out) + "\n")


def write_mtg(
    path: PathLike,
    classes: list[tuple[str, int]],
    rows: list[tuple[int, str, dict[str, float]]],
    features: list[str],
    relations: list[tuple[str, str, str]] | None = None,
) -> Path:
    """Write a multiscale MTG (FORM-A) from explicit entity rows.

    ``classes``: ``(symbol, scale)`` pairs (scale 0, the scene ``$``, is added);
    ``rows``: ``(column, code, {feature: value})`` in file order, codes written as given
    (``/P1``, ``^/A1``, ``^<M2``, ``+A2`` …; see the module docstring for how columns and
    ``^`` resolve references); ``features``: REAL feature names (missing values are left
    empty). ``relations``: DESCRIPTION rows ``(left, right, reltype)`` (default: ``<`` and
    ``+`` between every pair of same-scale classes).
    """
    if not rows:
        raise InputError(f"{os.fspath(path)}: no entities to write")
    ncol = max(col for col, _, _ in rows) + 1
    out = [
        "CODE :\tFORM-A",
        "",
        "CLASSES :",
        "SYMBOL\tSCALE\tDECOMPOSITION\tINDEXATION\tDEFINITION",
        "$\t0\tFREE\tFREE\tIMPLICIT",
    ]
    out += [f"{sym}\t{scale}\tFREE\tFREE\tEXPLICIT" for sym, scale in classes]
    out += ["", "DESCRIPTION :", "LEFT\tRIGHT\tRELTYPE\tMAX"]
    if relations is None:
        relations = [
            (a, b, r) for a, sa in classes for b, sb in classes if sa == sb for r in ("<", "+")
        ]
    out += [f"{a}\t{b}\t{r}\t?" for a, b, r in relations]
    out += ["", "FEATURES :", "NAME\tTYPE"] + [f"{f}\tREAL" for f in features] + ["", "MTG :"]
    out.append("ENTITY-CODE" + "\t" * ncol + "\t".join(features))
    for col, code, feats in rows:
        vals = ["" if feats.get(f) is None else repr(float(feats[f])) for f in features]
        out.append("\t" * col + code + "\t" * (ncol - col) + "\t".join(vals))
    return write_text(path, "\n".join(out) + "\n")


__all__ = ["read_graph", "write_graph", "write_mtg"]
