"""Readers for the digitised grass-leaf data in ``../shared/data/leaves`` (see its README).

Data units are centimetres (ADEL/ECHAP); :func:`wheat_leaves` and :func:`maize_leaves`
convert to metres. These readers are used by the preset derivation
(``bench/derive_leaf_presets.py``), tests and benchmarks — the package itself only needs
the derived numbers in ``leaf/presets.json``.
"""

from __future__ import annotations

import csv
import os
from collections import defaultdict
from pathlib import Path

import numpy as np

from biomorph.core.types import Array, PathLike
from biomorph.errors import FormatError
from biomorph.leaf.shape import LeafShape, MidribCollection

#: Environment variable naming the shared data folder (the one holding ``leaves/``).
DATA_ENV = "BIOMORPH_SHARED_DATA"


def shared_leaves(required: bool = True) -> Path | None:
    """The shared leaf-data folder, resolved only when asked (never at import).

    Search order: ``$BIOMORPH_SHARED_DATA/leaves`` if that variable is set; otherwise
    ``shared/data/leaves`` in the current directory and each of its parents, then in each
    parent of this source file (a source checkout beside ``../shared``).
    Raises :class:`FormatError` naming the places searched when ``required`` and absent,
    else returns ``None``.
    """
    tried: list[Path] = []
    env = os.environ.get(DATA_ENV)
    if env:
        tried.append(Path(env) / "leaves")
    else:
        cwd = Path.cwd().resolve()
        here = Path(__file__).resolve().parent
        for d in (cwd, *cwd.parents, *here.parents):
            cand = d / "shared" / "data" / "leaves"
            if cand not in tried:
                tried.append(cand)
    for cand in tried:
        if cand.is_dir():
            return cand
    if not required:
        return None
    more = " ..." if len(tried) > 3 else ""
    raise FormatError(
        tried[0],
        f"leaf data folder not found; set {DATA_ENV} to the folder "
        f"that holds leaves/ (searched {', '.join(map(str, tried[:3]))}"
        f"{more})",
    )


def __getattr__(name: str):
    if name == "SHARED_LEAVES":  # backwards-compatible, resolved lazily
        return shared_leaves()
    raise AttributeError(f"module 'biomorph.leaf.data' has no attribute {name!r}")


def _rows(path: PathLike, columns: tuple[str, ...]) -> list[tuple[int, list[float]]]:
    p = Path(path)
    if not p.is_file():
        raise FormatError(p, "file does not exist")
    out = []
    with p.open(newline="") as fh:
        reader = csv.DictReader(fh)
        missing = [c for c in columns if c not in (reader.fieldnames or [])]
        if missing:
            raise FormatError(
                p,
                f"missing column(s) {', '.join(missing)}; found "
                f"{', '.join(reader.fieldnames or [])}",
                line=1,
            )
        for i, row in enumerate(reader, start=2):
            try:
                out.append((i, [float(row[c]) for c in columns]))
            except (TypeError, ValueError) as exc:
                raise FormatError(p, f"non-numeric value in {row}", line=i) from exc
    return out


def read_xy(path: PathLike) -> dict[tuple[int, int], tuple[Array, Array]]:
    """Midribs ``rank,lindex,x,y`` → ``{(rank, lindex): (x, y)}`` in file order."""
    groups: dict[tuple[int, int], list[list[float]]] = defaultdict(list)
    for _, (rank, lindex, x, y) in _rows(path, ("rank", "lindex", "x", "y")):
        groups[(int(rank), int(lindex))].append([x, y])
    return {k: (np.array(v)[:, 0], np.array(v)[:, 1]) for k, v in groups.items()}


def read_sr(path: PathLike, key: str = "rankclass") -> dict:
    """Width profiles ``<key>,s,r`` (or ``rank,lindex,s,r``) → ``{key: (s, r)}``."""
    cols = ("rank", "lindex", "s", "r") if key == "rank,lindex" else (key, "s", "r")
    groups: dict = defaultdict(list)
    for _, vals in _rows(path, cols):
        k = (int(vals[0]), int(vals[1])) if key == "rank,lindex" else int(vals[0])
        groups[k].append(vals[-2:])
    return {k: (np.array(v)[:, 0], np.array(v)[:, 1]) for k, v in groups.items()}


def read_trajectories(path: PathLike) -> dict[int, MidribCollection]:
    """ECHAP median trajectories ``age,x,y,lindex`` → one :class:`MidribCollection` per class.

    Ages are phyllochrons since the leaf reached full extension (age = HS − rank), so the
    collections record ``full_extension_age = 0``."""
    by: dict[int, dict[float, list[list[float]]]] = defaultdict(lambda: defaultdict(list))
    for _, (age, x, y, lindex) in _rows(path, ("age", "x", "y", "lindex")):
        by[int(lindex)][age].append([x, y])
    out = {}
    for lindex, curves in by.items():
        ages = sorted(curves)
        pts = [np.array(curves[a]) for a in ages]
        out[lindex] = MidribCollection.from_curves(
            ages,
            [(p[:, 0], p[:, 1]) for p in pts],
            n=51,
            source=f"{Path(path).name} lindex={lindex}",
            full_extension_age=0.0,
        )  # age = Haun stage − rank: 0 at full extension
    return out


def drop_duplicate_points(x: Array, y: Array) -> tuple[Array, Array]:
    """Remove consecutive duplicate digitised points (the raw maize data holds some; the
    API itself rejects duplicates)."""
    keep = np.concatenate([[True], np.hypot(np.diff(x), np.diff(y)) > 0])
    return x[keep], y[keep]


def drop_basal_backstep(x: Array, y: Array) -> tuple[Array, Array]:
    """Remove the first digitised point after the base when the midrib turns back by more
    than 90° there: a blade cannot reverse within its first segment, so that point is a
    digitising slip at the collar (83 of the 450 So99 midribs have one; the shape and its
    insertion angle are then read from the base to the next point)."""
    if x.size < 4:
        return x, y
    a = np.arctan2(np.diff(y[:3]), np.diff(x[:3]))
    turn = abs((a[1] - a[0] + np.pi) % (2 * np.pi) - np.pi)
    if turn > np.pi / 2:
        return np.delete(x, 1), np.delete(y, 1)
    return x, y


def wheat_leaves(root: PathLike | None = None, width_ratio: float = 0.07) -> list[LeafShape]:
    """The 450 digitised wheat leaves of ``adel/So99.csv`` with their class width profiles
    (``adel/SRSo.csv``), in metres; maximal width = ``width_ratio · L``."""
    root = Path(root) if root is not None else shared_leaves()
    xy = read_xy(root / "adel" / "So99.csv")
    sr = read_sr(root / "adel" / "SRSo.csv")
    leaves = []
    for (rank, lindex), (x, y) in xy.items():
        s, r = sr[rank]
        x, y = drop_basal_backstep(*drop_duplicate_points(x, y))
        tmp = LeafShape.from_points(x, y, s, r, width=1.0, name=f"wheat r{rank} #{lindex}")
        leaves.append(tmp.with_(width=width_ratio * tmp.length))
    return leaves


def maize_leaves(root: PathLike | None = None, db: str = "leaves_db") -> list[LeafShape]:
    """Maize leaves of ``derived/maize_<db>_{xy,sr}.csv`` in metres (x,y and s,r
    normalised separately; ``L`` = measured length of the width profile)."""
    root = (Path(root) if root is not None else shared_leaves()) / "derived"
    xy = read_xy(root / f"maize_{db}_xy.csv")
    sr = read_sr(root / f"maize_{db}_sr.csv", key="rank,lindex")
    leaves = []
    for key, (x, y) in xy.items():
        if key not in sr:
            continue
        s, r = sr[key]
        x, y = drop_basal_backstep(*drop_duplicate_points(x, y))
        L = float((s[-1] - s[0]) * 0.01)
        leaves.append(
            LeafShape.from_points(x, y, s, r, length=L, name=f"maize r{key[0]} #{key[1]}")
        )
    return leaves


__all__ = [
    "DATA_ENV",
    "maize_leaves",
    "shared_leaves",
    "read_sr",
    "read_trajectories",
    "read_xy",
    "wheat_leaves",
]


def _median_profile(leaves: list[LeafShape], n: int = 51) -> tuple[Array, Array, Array]:
    s = np.linspace(0, 1, n)
    phi = np.median([lf.phi_at(s) for lf in leaves], axis=0)
    r = np.median([lf.r_at(s) for lf in leaves], axis=0)
    return s, phi, r / r.max()


def _r6(a) -> list[float]:
    return [float(f"{v:.6g}") for v in np.asarray(a, float).reshape(-1)]


def _rank_of(leaf: LeafShape) -> int:
    return int(leaf.name.split()[1][1:])


def _group_ranks(counts: dict[int, int]) -> list[list[int]]:
    """Contiguous rank groups holding at least half the median per-rank leaf count each
    (ranks with few digitised leaves are merged with the next rank; a short tail joins the
    last group)."""
    need = 0.5 * float(np.median(list(counts.values())))
    groups: list[list[int]] = []
    cur: list[int] = []
    for rank in sorted(counts):
        cur.append(rank)
        if sum(counts[k] for k in cur) >= need:
            groups.append(cur)
            cur = []
    if cur:
        if groups:
            groups[-1] += cur
        else:
            groups.append(cur)
    return groups


def _class_insertion(curves: Array, ref: Array) -> float:
    """Turn (radians) of the class shape about the leaf base that minimises its median
    distance to the leaves as digitised (0.25° grid over ±90°)."""
    cz = curves[..., 0] + 1j * curves[..., 1]
    rz = ref[:, 0] + 1j * ref[:, 1]
    best = (np.inf, 0.0)
    for a in np.radians(np.arange(-90.0, 90.0 + 1e-9, 0.25)):
        med = float(np.median(np.abs(cz - np.exp(1j * a) * rz).max(-1)))
        if med < best[0]:
            best = (med, float(a))
    return best[1]


def _insertion_sd(curves: Array, family: Array, dist: Array) -> float:
    """Robust standard deviation (degrees; IQR / 1.349) of the leaves' insertion angles
    about their shape family's medoid (pooled over families, so two families of a class
    do not count as insertion spread)."""
    from biomorph.leaf.fit import aligned_distances, medoid

    dev = []
    for j in np.unique(family):
        idx = np.flatnonzero(family == j)
        m = idx[medoid(curves[idx], dist[np.ix_(idx, idx)])]
        a = aligned_distances(curves[idx], curves[m])[1]
        dev.extend(np.degrees(a - np.median(a)))
    q25, q75 = np.percentile(dev, [25, 75])
    return float((q75 - q25) / 1.349)


def _class_entry(leaves: list[LeafShape], s_r: Array, r: Array, n: int = 101) -> dict:
    """Shape, ADEL-like member database and figures of one class of leaves.

    The class shape is the medoid of the class under the insertion-aligned distance
    (:func:`~biomorph.leaf.fit.aligned_distances`: the shape with the smallest median
    distance once each leaf's insertion angle is fitted), turned to the median of those
    fitted insertion angles (so it also sits where the class's leaves sit). Member 0 is
    that shape; members 1.. are the greedy medoids of the leaves as digitised (insertion
    angles included), which plants draw from like ADEL's database."""
    from biomorph.leaf.fit import (
        aligned_distances,
        aligned_pairwise,
        class_figures,
        class_members,
        curves_of,
        max_distances,
        medoid,
        pairwise,
        shape_families,
        unit_curve,
    )

    curves = curves_of(leaves)
    raw = pairwise(curves)
    dist = aligned_pairwise(curves)
    m = medoid(curves, dist)
    offsets = aligned_distances(curves, curves[m])[1]
    s = np.linspace(0, 1, n)
    turn = _class_insertion(curves, curves[m])
    phi = np.array(_r6(leaves[m].phi_at(s) + turn))  # as read back
    ref = unit_curve(lambda q: np.interp(q, s, phi))
    fig = class_figures(curves, ref, dist, aligned=True)
    fig_raw = class_figures(curves, ref, raw)
    _, fam, _ = shape_families(dist)
    spread_deg = _insertion_sd(curves, fam, dist)
    members = class_members(curves, dist=raw)
    phis = [list(phi)] + [_r6(leaves[k].phi_at(s)) for k in members]
    near = np.minimum(max_distances(curves, ref), raw[:, members].min(axis=1))
    q25, q75 = np.percentile(np.degrees(offsets), [25, 75])
    return {
        "n_leaves": fig["n"],
        "medoid": leaves[m].name,
        "s": _r6(s),
        "phi": list(phi),
        "s_r": _r6(s_r),
        "r": _r6(r / r.max()),
        "length": float(f"{np.median([lf.length for lf in leaves]):.6g}"),
        "width": float(f"{np.median([lf.width for lf in leaves]):.6g}"),
        "median_maxdist": round(fig["median_maxdist"], 4),
        "spread": round(fig["spread"], 4),
        "median_maxdist_raw": round(fig_raw["median_maxdist"], 4),
        "spread_raw": round(fig_raw["spread"], 4),
        "insertion_iqr_deg": [round(float(q25), 2), round(float(q75), 2)],
        "insertion_sd_deg": round(spread_deg, 2),
        "chord_deg": round(fig["chord_deg"], 2),
        "members_phi": phis,
        "members_maxdist": round(float(np.median(near)), 4),
    }


#: Mature maize plant (literature figures, see docs/leaf.md "Mature maize"): ranks of the
#: default plant, leaves above the ear leaf (the largest leaf), one-sided leaf area per plant
#: (m²) and length/width of the largest blade.
MAIZE_MATURE = {
    "n_ranks": 16,
    "leaves_above_ear": 5,
    "plant_leaf_area_m2": 0.5,
    "largest_length_to_width": 10.0,
}


def bell_leaf_fractions(n_ranks: int, largest_rank: float) -> Array:
    """Fraction of the plant's leaf area carried by each rank ``1..n_ranks``.

    Yang & Alley (2005, Agron. J. 97:41) reduced bell model of maize leaf area per rank:
    ``F(n) = F0 · exp(−(F0 · (n − n0))² / 0.3542)`` with ``F = S/S_T`` (leaf area over the
    plant's total); ``F0`` (the largest leaf's share) is solved so that ``Σ F = 1`` over the
    ranks present (bisection; ``Σ F`` is monotone in ``F0`` on ``(0, 1]`` for these ranks).
    """
    n = np.arange(1, n_ranks + 1, dtype=float)

    def total(f0: float) -> float:
        return float(np.sum(f0 * np.exp(-((f0 * (n - largest_rank)) ** 2) / 0.3542)))

    lo, hi = 1e-4, 1.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if total(mid) < 1.0 else (lo, mid)
    f0 = 0.5 * (lo + hi)
    return f0 * np.exp(-((f0 * (n - largest_rank)) ** 2) / 0.3542)


def mature_maize_blades(
    form_factors: Array, width_exponent: float, params: dict | None = None
) -> dict[str, Array]:
    """Per-rank blade length and width (m) of a mature maize plant.

    Leaf area per rank: :func:`bell_leaf_fractions` × the plant's leaf area, the largest
    leaf ``leaves_above_ear`` ranks below the top. Each area ``A = ff · L · W`` is split
    with the width allometry ``W ∝ L^β`` (``β = width_exponent``, fitted on the digitised
    mature leaves) and the largest blade's ``L/W``; ``ff`` is the form factor of the width
    profile that rank's leaves use (so the meshed area equals the table's).
    """
    p = {**MAIZE_MATURE, **(params or {})}
    n = int(p["n_ranks"])
    ff = np.asarray(form_factors, float)
    area = bell_leaf_fractions(n, n - p["leaves_above_ear"]) * p["plant_leaf_area_m2"]
    k = int(np.argmax(area))
    w0 = np.sqrt(area[k] / (ff[k] * p["largest_length_to_width"]))
    l0 = area[k] / (ff[k] * w0)
    # W = w0 (L/l0)^β and A = ff L W  =>  L = l0 (A ff0 / (A0 ff))^(1/(1+β))
    length = l0 * (area * ff[k] / (area[k] * ff)) ** (1.0 / (1.0 + width_exponent))
    width = area / (ff * length)
    return {
        "rank": np.arange(1, n + 1, dtype=float),
        "L_blade": length,
        "W_blade": width,
        "area": area,
    }


def _wheat_dims(root: Path) -> dict:
    cols = (
        "xn",
        "L_blade",
        "W_blade",
        "L_sheath",
        "L_internode",
        "W_sheath",
        "H_col",
        "W_internode",
    )
    rows = np.array([v for _, v in _rows(root / "adel" / "Wheat_dimension_profiles.csv", cols)])
    return {c: _r6(rows[:, k] * (1 if c == "xn" else 0.01)) for k, c in enumerate(cols)}


def _maize_rank_classes(maize: list[LeafShape], shapes: dict) -> tuple[dict, dict]:
    """One class per rank of the mature maize plant: the rank's blade length and width
    (:func:`mature_maize_blades`) and the shape class of the digitised leaves of that rank.

    The digitised plant is young: its median blade length peaks at one rank and falls
    above it while the widths still rise — the upper leaves are still extending in the
    whorl (erect, chord 80–86°); take the longest rank as its last ligulated leaf. Maize
    has no midrib collection, but a single-date plant is an age series: its rank ``q``
    has been ligulated for ``r_lig − q`` phyllochrons. The mature plant (last leaf ``n``
    just ligulated) gives rank ``r`` the shape of the digitised rank with the same time
    since ligulation, ``q = r − (n − r_lig)``, clipped to the digitised ranks (older
    leaves take the oldest group)."""
    ranks = np.array([_rank_of(lf) for lf in maize])
    lengths = np.array([lf.length for lf in maize])
    widths = np.array([lf.width for lf in maize])
    med = {int(r): float(np.median(lengths[ranks == r])) for r in np.unique(ranks)}
    r_mature = max(med, key=lambda r: med[r])
    ok = ranks <= r_mature
    beta = float(np.polyfit(np.log(lengths[ok]), np.log(widths[ok]), 1)[0])
    of_rank = {r: k for k, c in shapes.items() for r in c["ranks"]}
    n = int(MAIZE_MATURE["n_ranks"])
    lowest = min(of_rank)
    keys = []
    for r in range(1, n + 1):
        q = min(max(r - (n - r_mature), lowest), r_mature)
        while q not in of_rank:  # a rank absent from the data: the next lower one
            q -= 1
        keys.append(of_rank[q])
    ff = np.array([np.trapezoid(shapes[k]["r"], shapes[k]["s_r"]) for k in keys])
    dims = mature_maize_blades(ff, beta)
    classes = {
        str(r): {
            "ranks": [r],
            "shape_class": k,
            "length": float(f"{dims['L_blade'][r - 1]:.6g}"),
            "width": float(f"{dims['W_blade'][r - 1]:.6g}"),
            "area": float(f"{dims['area'][r - 1]:.6g}"),
        }
        for r, k in zip(range(1, n + 1), keys, strict=True)
    }
    info = {
        **MAIZE_MATURE,
        "width_exponent": round(beta, 4),
        "longest_digitised_rank": r_mature,
        "source": "per-rank leaf area: Yang & Alley 2005 bell model; plant leaf area, ear "
        "position and largest L/W: literature figures (docs/leaf.md); width exponent and "
        "form factors: maize_leaves_db",
    }
    return classes, info


def derive_presets(root: PathLike | None = None) -> dict:
    """Derive the ``maize``, ``wheat`` and ``grass`` presets from the shared data.

    * wheat — one class per So99 rank class (1..6): its medoid midrib (see
      :mod:`biomorph.leaf.fit`), its SRSo width profile and a member database; the single
      mature preset is the medoid of all 450 midribs with the mean SRSo width; length and
      width of the longest blade of ``Wheat_dimension_profiles.csv`` (also kept whole, in
      metres, as the per-rank dimension table); the Tremie12 midrib collection N(age, s)
      (29 ages, −2..12 phyllochrons from full extension) for growing leaves;
    * maize — one class per group of ranks of ``leaves_db`` (groups hold at least half the
      median per-rank count): medoid midrib, median relative width, median length and
      width; the single mature preset is the medoid of all 158 leaves, with the median
      length and width of the leaves at least 80 % as long as the longest;
    * grass — the wheat shapes of the most bent rank class with a narrow blade and a half
      twist. Twist and undulation are not in the data: they are set by hand and marked so.
    """
    from biomorph.leaf.fit import curves_of, medoid

    root = Path(root) if root is not None else shared_leaves()
    out: dict = {}
    wheat = wheat_leaves(root)
    s = np.linspace(0, 1, 101)
    sr = read_sr(root / "adel" / "SRSo.csv")
    r_w = np.mean([np.interp(s, *sr[k]) for k in sorted(sr)], axis=0)
    dims = _wheat_dims(root)
    i_max = int(np.argmax(dims["L_blade"]))
    L_w, W_w = dims["L_blade"][i_max], dims["W_blade"][i_max]
    traj = read_trajectories(
        root / "adel" / "echap_leaf_data" / "median_leaf_trajectories_Tremie12.csv"
    )[1]
    w_all = wheat[medoid(curves_of(wheat))]
    classes = {
        str(k): _class_entry([lf for lf in wheat if _rank_of(lf) == k], *sr[k]) for k in sorted(sr)
    }
    out["wheat"] = {
        "source": "So99.csv (450 midribs: medoid of all, and per rank class), SRSo.csv "
        "(widths per class), Wheat_dimension_profiles.csv (longest blade, "
        "per-rank dimensions), Tremie12 trajectories",
        "length": float(f"{L_w:.6g}"),
        "width": float(f"{W_w:.6g}"),
        "s": _r6(s),
        "phi": _r6(w_all.phi_at(s)),
        "s_r": _r6(s),
        "r": _r6(r_w / r_w.max()),
        "twist_deg": 0.0,
        "undulation": 0.0,
        "wavelength": 0.05,
        "collection": {
            "ages": _r6(traj.ages),
            "s": _r6(traj.s),
            "phi": [_r6(row) for row in traj.phi],
            "source": traj.source,
            "full_extension_age": 0.0,
        },
        "class_rule": "rank_from_top",
        "classes": classes,
        "dimensions": dims,
    }
    maize = maize_leaves(root)
    lmax = max(lf.length for lf in maize)
    big = [lf for lf in maize if lf.length >= 0.8 * lmax]
    counts: dict[int, int] = {}
    for lf in maize:
        counts[_rank_of(lf)] = counts.get(_rank_of(lf), 0) + 1
    groups = _group_ranks(counts)
    m_shapes = {}
    for grp in groups:
        members = [lf for lf in maize if _rank_of(lf) in grp]
        r_m = np.median([lf.r_at(s) for lf in members], axis=0)
        entry = _class_entry(members, s, r_m)
        entry["ranks"] = grp
        # "g" keys: shape groups of digitised ranks, distinct from the per-rank classes
        m_shapes["g" + ("-".join(map(str, (grp[0], grp[-1]))) if len(grp) > 1 else str(grp[0]))] = (
            entry
        )
    m_classes, mature_info = _maize_rank_classes(maize, m_shapes)
    m_all = maize[medoid(curves_of(maize))]
    out["maize"] = {
        "source": f"maize_leaves_db (medoid of the {len(maize)} leaves; length and width: "
        f"median of the {len(big)} leaves >= 80% of the longest; classes per rank "
        "group)",
        "length": float(f"{np.median([lf.length for lf in big]):.6g}"),
        "width": float(f"{np.median([lf.width for lf in big]):.6g}"),
        "s": _r6(s),
        "phi": _r6(m_all.phi_at(s)),
        "s_r": _r6(s),
        "r": _r6(np.median([lf.r_at(s) for lf in big], axis=0)),
        "twist_deg": 30.0,
        "undulation": 0.004,
        "wavelength": 0.06,
        "hand_set": ["twist_deg", "undulation", "wavelength"],
        "class_rule": "rank_table",
        "classes": m_classes,
        "shape_classes": m_shapes,
        "mature_dimensions": mature_info,
    }
    bent = min(sr, key=lambda k: np.median([lf.phi[-1] for lf in wheat if _rank_of(lf) == k]))
    cls_leaves = [lf for lf in wheat if _rank_of(lf) == bent]
    sm, phi, _ = _median_profile(cls_leaves)
    out["grass"] = {
        "source": f"So99.csv rank class {bent} (most bent; median angle), SRSo class {bent}",
        "length": 0.3,
        "width": 0.006,
        "s": _r6(sm),
        "phi": _r6(phi),
        "s_r": _r6(sm),
        "r": _r6(np.interp(sm, *sr[bent]) / sr[bent][1].max()),
        "twist_deg": 180.0,
        "undulation": 0.0,
        "wavelength": 0.05,
        "hand_set": ["length", "width", "twist_deg"],
    }
    return out


__all__ += ["derive_presets", "drop_basal_backstep", "drop_duplicate_points"]


#: Mature maize stem (literature figures, see docs/leaf.md "Mature maize stem"). Lengths in
#: metres, on the 16-rank plant of :data:`MAIZE_MATURE`; other leaf counts read the profile
#: on the normalised rank (as the blades do).
MAIZE_STEM = {
    # nodes 1..5 stay in the crown at the soil: the growing point is below ground until
    # V5-V6 and stalk elongation starts after (Ritchie, Hanway & Benson 1993)
    "unelongated_internodes": 5,
    "unelongated_internode_m": 0.01,
    # final internode length rises steeply over the first ~3 elongated phytomers to a
    # plateau of 0.17-0.20 m around the ear, slightly shorter above it (Fournier &
    # Andrieu 2000, cv. Dea)
    "rise_phytomers": 3,
    "max_internode_m": 0.185,
    "top_internode_fraction": 0.8,
    # sheaths lengthen from the base to the ear region (~0.15-0.17 m) and shorten slightly
    # above (Andrieu, Hillier & Birch 2006)
    "sheath_lowest_m": 0.04,
    "sheath_ear_m": 0.16,
    "sheath_top_m": 0.13,
    # stem diameter 2.5 cm at the base to 1.5 cm under the tassel (Morrison et al. 1994:
    # internodes 1.5-2.5 cm); the sheath wraps the internode (+2 mm)
    "internode_base_diameter_m": 0.025,
    "internode_top_diameter_m": 0.015,
    "sheath_wall_m": 0.002,
}


def _ramp(x: Array, xp: list[float], fp: list[float]) -> Array:
    return np.interp(x, xp, fp)


def mature_maize_stem(
    params: dict | None = None, blade_params: dict | None = None
) -> dict[str, Array]:
    """Per-rank internode and sheath length and diameter (m) of the mature maize plant.

    Profile (16 ranks by default, ear leaf ``leaves_above_ear`` below the top, see
    :data:`MAIZE_MATURE` and :data:`MAIZE_STEM`): internodes of the crown nodes stay at
    ``unelongated_internode_m``; above them the final length rises linearly over
    ``rise_phytomers`` above the crown to ``max_internode_m``, holds it up to the ear and
    falls linearly to ``top_internode_fraction`` of it at the top rank; sheaths rise
    linearly from ``sheath_lowest_m`` at rank 1 to ``sheath_ear_m`` at the ear and fall
    to ``sheath_top_m`` at the top; diameters taper linearly from base to top.
    Internode ``r`` spans node ``r`` to node ``r + 1`` (the plant's convention)."""
    p = {**MAIZE_STEM, **(params or {})}
    b = {**MAIZE_MATURE, **(blade_params or {})}
    n = int(b["n_ranks"])
    rank = np.arange(1, n + 1, dtype=float)
    ear = float(max(n - b["leaves_above_ear"], 1))
    k = float(min(p["unelongated_internodes"], ear - 1))
    lmax, l0 = p["max_internode_m"], p["unelongated_internode_m"]
    internode = np.where(
        rank <= k,
        l0,
        _ramp(rank, [k, min(k + p["rise_phytomers"], ear), max(ear, k + 1), float(max(n, ear + 1))],
              [l0, lmax, lmax, lmax * p["top_internode_fraction"]]),
    )  # fmt: skip
    sheath = _ramp(rank, [1.0, ear, float(max(n, ear + 1))],
                   [p["sheath_lowest_m"], p["sheath_ear_m"], p["sheath_top_m"]])  # fmt: skip
    w_int = _ramp(rank, [1.0, float(max(n, 2))],
                  [p["internode_base_diameter_m"], p["internode_top_diameter_m"]])  # fmt: skip
    return {
        "rank": rank,
        "L_internode": internode,
        "L_sheath": sheath,
        "W_internode": w_int,
        "W_sheath": w_int + 2 * p["sheath_wall_m"],
    }


#: Maize leaf senescence (see docs/leaf.md "Maize senescence"). Thermal times in °Cd above
#: the maize base temperature (8 °C).
MAIZE_SENESCENCE = {
    # silking: 2-3 days after the tassel is out (Ritchie, Hanway & Benson 1993, VT -> R1),
    # taken as one 50 °Cd phyllochron after the last ligule
    "silking_after_last_ligule_cd": 50.0,
    # plant leaf senescence is bilinear in thermal time, starting ~500 °Cd (base 8 °C)
    # before silking, 1.4 then 5.5 cm² per plant per °Cd (Borrás, Maddonni & Otegui 2003)
    "onset_before_silking_cd": 500.0,
    "rate1_m2_per_cd": 1.4e-4,
    "rate2_m2_per_cd": 5.5e-4,
    # the fast phase starts half-way through grain filling (Valentinuz & Tollenaar 2004:
    # 0.44 %/d in the first half, 1.87 %/d in the second); silking to physiological
    # maturity 750 °Cd (CERES-Maize P5, base 8 °C: 680-850 °Cd)
    "grain_filling_cd": 750.0,
    "fast_phase_after_silking": 0.5,
    # the rates are per plant of this leaf area (our mature plant, MAIZE_MATURE); another
    # plant's rates scale with its leaf area
    "reference_plant_area_m2": 0.5,
}


def maize_senescence_stages(
    areas: Array, phyllochron: float, params: dict | None = None
) -> tuple[Array, Array]:
    """Haun stages ``(ssi, disp)`` per rank of a maize main stem whose blades have one-sided
    ``areas`` (m², rank 1 first) and whose last leaf ligulates at Haun stage ``n``.

    The plant's senescent leaf area ``S(t)`` follows the bilinear course of
    :data:`MAIZE_SENESCENCE` (onset before silking, slow then fast rate); as in ADEL's
    senescent-stage index the leaves senesce from the bottom up, one after the other, so
    leaf ``r`` starts when ``S`` reaches the area of the leaves below it and has died when
    ``S`` reaches the area up to it. ``ssi`` is held at or after ligulation."""
    p = {**MAIZE_SENESCENCE, **(params or {})}
    a = np.asarray(areas, float)
    n = a.size
    k = a.sum() / p["reference_plant_area_m2"]
    r1, r2 = k * p["rate1_m2_per_cd"], k * p["rate2_m2_per_cd"]
    silk = n * phyllochron + p["silking_after_last_ligule_cd"]
    t0 = silk - p["onset_before_silking_cd"]
    tb = silk + p["fast_phase_after_silking"] * p["grain_filling_cd"]
    sb = r1 * (tb - t0)
    cum = np.concatenate([[0.0], np.cumsum(a)])
    t = np.where(cum <= sb, t0 + cum / r1, tb + (cum - sb) / r2) / phyllochron
    col = np.arange(1, n + 1, dtype=float)
    ssi = np.maximum(t[:-1], col)
    return ssi, np.maximum(t[1:], ssi + 1e-3)


__all__ += ["MAIZE_SENESCENCE", "MAIZE_STEM", "maize_senescence_stages", "mature_maize_stem"]
