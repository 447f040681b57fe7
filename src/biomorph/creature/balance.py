"""Static balance: support polygon, stability margin and tipping torques (new beyond the seed).

The seed asks for torques ``M = r × F`` about the ground contacts, reduced to the sagittal
plane. We do the 3-D version: the support polygon is the convex hull of the contact patches
on the ground (x, z); the creature stands if its centre of mass projects inside with a
margin. For every support edge the restoring torque is ``m g d`` with ``d`` the signed
distance of the projected centre of mass to the edge (positive inside); the smallest is the
torque needed to tip the creature over that edge.

The margin is asked for as a share of the creature's size, the larger of its body length
and its centre of mass's height above the ground: a tall, short creature (a biped standing
on two hooves) must keep its centre of mass as far inside as a long one of that height, so
the tipping angle ``atan(margin / height)`` is never below ``atan(min_margin_fraction)``
(1.15° at the default 0.02). Measured against the body length only, such a creature passed
with a 0.7° tipping angle and fell over in MuJoCo (issue 14, sixth round).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numba
import numpy as np
from numpy.typing import NDArray

G = 9.81


@dataclass(frozen=True)
class BalanceReport:
    """Result of the balance check (metres, kg, N·m)."""

    applicable: bool  # False without legs on the ground (swims / rests on body)
    stable: bool
    margin: float  # signed distance of the COM to the polygon boundary (m)
    margin_fraction: float  # margin / size (the larger of body length and COM height)
    sagittal_margin: float  # the seed's 2-D view: COM x inside the contacts' x-range
    tipping_torque: float  # smallest restoring torque about a support edge (N·m)
    com: tuple[float, float, float]
    support: tuple[tuple[float, float], ...]  # polygon (x, z), counter-clockwise
    mass: float
    repairs: int = 0
    resamples: int = 0
    reason: str = ""

    def to_dict(self) -> dict:
        return asdict(self)


def convex_hull(points: NDArray) -> NDArray[np.float64]:
    """Counter-clockwise convex hull (Andrew's monotone chain) of 2-D points ``(n, 2)``."""
    pts = sorted(set(map(tuple, np.asarray(points, float).round(12).tolist())))
    if len(pts) <= 2:
        return np.array(pts, float).reshape(-1, 2)
    return _monotone_chain(np.array(pts, float))


@numba.njit(cache=True)
def _monotone_chain(p: np.ndarray) -> np.ndarray:  # pragma: no cover - compiled
    """Andrew's monotone chain on sorted, distinct points ``p (n, 2)``: the lower hull then
    the upper one, each without its last point (the same cross products as the plain loop)."""
    n = p.shape[0]
    out = np.empty((2 * n, 2))
    k = 0
    for half in range(2):
        start = k
        for t in range(n):
            i = t if half == 0 else n - 1 - t
            qx, qy = p[i, 0], p[i, 1]
            while k - start >= 2:
                ox, oy = out[k - 2, 0], out[k - 2, 1]
                ax, ay = out[k - 1, 0], out[k - 1, 1]
                if (ax - ox) * (qy - oy) - (ay - oy) * (qx - ox) <= 0:
                    k -= 1
                else:
                    break
            out[k, 0], out[k, 1] = qx, qy
            k += 1
        k -= 1  # drop the last point of this half
    return out[:k].copy()


def edge_distances(poly: NDArray, q: NDArray) -> NDArray[np.float64]:
    """Signed distances (positive inside) of point ``q`` to each edge of a CCW polygon."""
    a = poly
    b = np.roll(poly, -1, axis=0)
    e = b - a
    n = np.linalg.norm(e, axis=1)
    cr = e[:, 0] * (q[1] - a[:, 1]) - e[:, 1] * (q[0] - a[:, 0])
    return cr / np.where(n > 0, n, 1.0)


@numba.njit(cache=True)
def _min_edge_distance(poly: np.ndarray, qx: float, qy: float) -> float:  # pragma: no cover
    """``edge_distances(poly, q).min()`` compiled (the same operations per edge)."""
    k = poly.shape[0]
    best = np.inf
    for i in range(k):
        j = i + 1 if i + 1 < k else 0
        ex, ey = poly[j, 0] - poly[i, 0], poly[j, 1] - poly[i, 1]
        n = np.sqrt(ex * ex + ey * ey)
        cr = ex * (qy - poly[i, 1]) - ey * (qx - poly[i, 0])
        d = cr / (n if n > 0 else 1.0)
        if d < best or i == 0:
            best = d
    return best


def evaluate(
    com: NDArray,
    mass: float,
    patches: NDArray,
    body_length: float,
    min_margin_fraction: float = 0.01,
    com_height: float = 0.0,
) -> BalanceReport:
    """Balance of a creature with centre of mass ``com (3,)`` (world, Y up) standing on
    contact patches ``patches (k, 2)`` (x, z corner points on the ground); the margin is
    measured against the larger of ``body_length`` and ``com_height`` (the centre of
    mass's height above the ground)."""
    c = np.asarray(com, float)
    if patches is None or len(patches) == 0:
        return BalanceReport(
            False,
            True,
            0.0,
            0.0,
            0.0,
            0.0,
            tuple(map(float, c)),
            (),
            float(mass),
            reason="no legs with ground contact",
        )
    q = np.array([c[0], c[2]])
    poly = convex_hull(patches)
    x0, x1 = float(np.min(patches[:, 0])), float(np.max(patches[:, 0]))
    sag = min(q[0] - x0, x1 - q[0])
    if len(poly) < 3:
        margin = -float(np.min(np.linalg.norm(poly - q, axis=1))) if len(poly) else -1.0
        torque = mass * G * margin
    else:
        margin = float(_min_edge_distance(poly, float(q[0]), float(q[1])))
        torque = float(mass * G * margin)
    frac = margin / max(body_length, com_height, 1e-12)
    stable = frac >= min_margin_fraction
    return BalanceReport(
        True,
        bool(stable),
        margin,
        float(frac),
        float(sag),
        float(torque),
        tuple(map(float, c)),
        tuple(map(tuple, poly.tolist())),
        float(mass),
    )
