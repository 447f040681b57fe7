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
from numpy.typing import NDArray

from biomorph.errors import FormatError
from biomorph.leaf.shape import LeafShape, MidribCollection

Array = NDArray[np.float64]
PathLike = str | os.PathLike[str]

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
    raise FormatError(tried[0], f"leaf data folder not found; set {DATA_ENV} to the folder "
                                f"that holds leaves/ (searched {', '.join(map(str, tried[:3]))}"
                                f"{more})")


def __getattr__(name: str):
    if name == "SHARED_LEAVES":   # backwards-compatible, resolved lazily
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
            raise FormatError(p, f"missing column(s) {', '.join(missing)}; found "
                                 f"{', '.join(reader.fieldnames or [])}", line=1)
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
    """ECHAP median trajectories ``age,x,y,lindex`` → one :class:`MidribCollection` per class."""
    by: dict[int, dict[float, list[list[float]]]] = defaultdict(lambda: defaultdict(list))
    for _, (age, x, y, lindex) in _rows(path, ("age", "x", "y", "lindex")):
        by[int(lindex)][age].append([x, y])
    out = {}
    for lindex, curves in by.items():
        ages = sorted(curves)
        pts = [np.array(curves[a]) for a in ages]
        out[lindex] = MidribCollection.from_curves(
            ages, [(p[:, 0], p[:, 1]) for p in pts], n=51,
            source=f"{Path(path).name} lindex={lindex}")
    return out


def drop_duplicate_points(x: Array, y: Array) -> tuple[Array, Array]:
    """Remove consecutive duplicate digitised points (the raw maize data holds some; the
    API itself rejects duplicates)."""
    keep = np.concatenate([[True], np.hypot(np.diff(x), np.diff(y)) > 0])
    return x[keep], y[keep]


def wheat_leaves(root: PathLike | None = None, width_ratio: float = 0.07
                 ) -> list[LeafShape]:
    """The 450 digitised wheat leaves of ``adel/So99.csv`` with their class width profiles
    (``adel/SRSo.csv``), in metres; maximal width = ``width_ratio · L``."""
    root = Path(root) if root is not None else shared_leaves()
    xy = read_xy(root / "adel" / "So99.csv")
    sr = read_sr(root / "adel" / "SRSo.csv")
    leaves = []
    for (rank, lindex), (x, y) in xy.items():
        s, r = sr[rank]
        x, y = drop_duplicate_points(x, y)
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
        x, y = drop_duplicate_points(x, y)
        L = float((s[-1] - s[0]) * 0.01)
        leaves.append(LeafShape.from_points(x, y, s, r, length=L,
                                            name=f"maize r{key[0]} #{key[1]}"))
    return leaves


__all__ = ["DATA_ENV", "maize_leaves", "shared_leaves", "read_sr", "read_trajectories", "read_xy",
           "wheat_leaves"]


def _median_profile(leaves: list[LeafShape], n: int = 51) -> tuple[Array, Array, Array]:
    s = np.linspace(0, 1, n)
    phi = np.median([lf.phi_at(s) for lf in leaves], axis=0)
    r = np.median([lf.r_at(s) for lf in leaves], axis=0)
    return s, phi, r / r.max()


def _r6(a) -> list[float]:
    return [float(f"{v:.6g}") for v in np.asarray(a, float).reshape(-1)]


def derive_presets(root: PathLike | None = None) -> dict:
    """Derive the ``maize``, ``wheat`` and ``grass`` presets from the shared data.

    * wheat — median tangent-angle profile φ(s) of the 450 So99 midribs, mean of the six
      SRSo width classes, length and width of the longest blade of
      ``Wheat_dimension_profiles.csv``, and the Tremie12 midrib collection N(age, s)
      (29 ages) for growing leaves;
    * maize — median φ(s) and relative width of the ``leaves_db`` maize leaves at least
      80 % as long as the longest, their median length and maximal width;
    * grass — the wheat shapes of the most bent rank class with a narrow blade
      (width/length = 0.025 of the wheat leaves' own ratio scaled) and a half twist.
      Twist and undulation are not in the data: they are set by hand and marked so.
    """
    root = Path(root) if root is not None else shared_leaves()
    out: dict = {}
    wheat = wheat_leaves(root)
    s, phi, _ = _median_profile(wheat)
    sr = read_sr(root / "adel" / "SRSo.csv")
    r_w = np.mean([np.interp(s, *sr[k]) for k in sorted(sr)], axis=0)
    dims = _rows(root / "adel" / "Wheat_dimension_profiles.csv", ("L_blade", "W_blade"))
    dims_a = np.array([v for _, v in dims])
    i_max = int(np.argmax(dims_a[:, 0]))
    L_w, W_w = dims_a[i_max] * 0.01
    traj = read_trajectories(root / "adel" / "echap_leaf_data" /
                             "median_leaf_trajectories_Tremie12.csv")[1]
    out["wheat"] = {
        "source": "So99.csv (450 midribs, median angle), SRSo.csv (mean width), "
                  "Wheat_dimension_profiles.csv (longest blade), Tremie12 trajectories",
        "length": float(f"{L_w:.6g}"), "width": float(f"{W_w:.6g}"),
        "s": _r6(s), "phi": _r6(phi), "s_r": _r6(s), "r": _r6(r_w / r_w.max()),
        "twist_deg": 0.0, "undulation": 0.0, "wavelength": 0.05,
        "collection": {"ages": _r6(traj.ages), "s": _r6(traj.s),
                       "phi": [_r6(row) for row in traj.phi], "source": traj.source},
    }
    maize = maize_leaves(root)
    lmax = max(lf.length for lf in maize)
    big = [lf for lf in maize if lf.length >= 0.8 * lmax]
    s, phi, r_m = _median_profile(big)
    out["maize"] = {
        "source": f"maize_leaves_db (median of the {len(big)} leaves >= 80% of the longest)",
        "length": float(f"{np.median([lf.length for lf in big]):.6g}"),
        "width": float(f"{np.median([lf.width for lf in big]):.6g}"),
        "s": _r6(s), "phi": _r6(phi), "s_r": _r6(s), "r": _r6(r_m),
        "twist_deg": 30.0, "undulation": 0.004, "wavelength": 0.06,
        "hand_set": ["twist_deg", "undulation", "wavelength"],
    }
    ranks = sorted({int(lf.name.split()[1][1:]) for lf in wheat})
    bent = min(ranks, key=lambda k: np.median(
        [lf.phi[-1] for lf in wheat if lf.name.split()[1] == f"r{k}"]))
    cls_leaves = [lf for lf in wheat if lf.name.split()[1] == f"r{bent}"]
    s, phi, _ = _median_profile(cls_leaves)
    out["grass"] = {
        "source": f"So99.csv rank class {bent} (most bent; median angle), SRSo class {bent}",
        "length": 0.3, "width": 0.006,
        "s": _r6(s), "phi": _r6(phi), "s_r": _r6(s),
        "r": _r6(np.interp(s, *sr[bent]) / sr[bent][1].max()),
        "twist_deg": 180.0, "undulation": 0.0, "wavelength": 0.05,
        "hand_set": ["length", "width", "twist_deg"],
    }
    return out


__all__ += ["derive_presets", "drop_duplicate_points"]
