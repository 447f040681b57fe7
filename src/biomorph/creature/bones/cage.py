"""The trunk's cross-sections, the rib cage round them and the shoulder blade on its side.

The trunk is the chain of soft-tissue masses of the trunk vertebrae: vertebra ``j`` has a
section of centre ``Creature.mass_center[j]`` (a vertebra without mass of its own takes
its nearest massive neighbour's offset) and radius ``TRUNK_SHARE`` × the mean
half-size of its mass box (``Creature.mass_size``). The body envelope
(:mod:`biomorph.creature.skin`) puts one sphere of that radius at that centre, and the rib
cage is built round the same sections, so ribs follow the trunk's depth and stay inside the
skin by construction (``BODY_WALL``):

* each thoracic vertebra carries a pair of ribs in the plane across its spine: a curve from
  the transverse process (``(0.3 × box width)`` out from the centrum), arching laterally
  and ventrally round the section's centre at ``(1 − BODY_WALL) × radius``, to the
  ventral midline (true ribs, the front ``TRUE_RIBS`` of the thoracic vertebrae: the
  sternum joins them) or to ``FLOATING_REACH`` of the way round (false/floating ribs); each
  rib slopes caudally by ``RIB_SLOPE`` vertebra lengths on the way down, as mammal ribs do;
* the sternum: one sternebra per true-rib vertebra on the ventral midline;
* fish: pleural ribs round the body cavity (no sternum), ``PLEURAL_REACH`` of the way;
* the scapula: a blade from the glenoid (the shoulder joint, the girdle bone's far end)
  dorsally and caudally at ``SCAPULA_INCLINATION`` of its class, ``SCAPULA_LENGTH`` ×
  the humerus long, laid on the cage's side (its dorsal end pushed out to the section's
  surface) and no higher than the tops of the neural spines.

Constants and where they come from:

* ``TRUNK_SHARE`` 0.42: the share of the mass box's mean half-size the envelope's trunk
  sphere takes (the skin's own rule, kept from issue 14's first envelope);
* ``BODY_WALL`` 0.16: the thoracic wall outside the ribs (intercostal muscles, fat, skin)
  as a share of the chest radius — about 1.5–2 cm over a dog's 10–12 cm chest radius;
* ``RIB_SLOPE`` 1.2 vertebra lengths: the caudal lean of a mid-thoracic rib in dog and horse
  skeletons (the ventral end lies about one intercostal space behind its head);
* ``SCAPULA_LENGTH`` 0.9 × humerus: dog and horse scapulae are 0.85–1.0 of the humerus;
* ``SCAPULA_INCLINATION`` from the horizontal: mammals 58° (the scapular spine of dogs and
  horses lies 50–65° from the horizontal), reptiles and amphibians 70° (an upright
  plate), birds 12° (a sabre-shaped blade along the ribs, parallel to the spine).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from biomorph.creature.bones.prim import SIDES, tubes
from biomorph.creature.creature import Creature

TRUNK_SHARE = 0.42
BODY_WALL = 0.16
RIB_SLOPE = 1.2
#: share of the thoracic vertebrae (from the front) whose ribs reach the sternum
TRUE_RIBS = 0.6
#: floating ribs end this far round (share of a half turn from the dorsal midline)
FLOATING_REACH = 0.72
#: fish pleural ribs line the body cavity this far round (share of a half turn)
PLEURAL_REACH = 0.8
SCAPULA_LENGTH = 0.9
SCAPULA_INCLINATION = {"mammal": 58.0, "reptile": 70.0, "amphibian": 70.0, "bird": 12.0}
_TRUNK_REGIONS = ("back", "neck", "tail")


def trunk_sections(c: Creature) -> tuple[NDArray[np.int64], NDArray, NDArray]:
    """Spine joints with a trunk section, their centres ``(s, 3)`` and radii ``(s,)``."""
    idx = np.array(
        [
            j
            for j in range(len(c))
            if c.kind[j] == "spine" and c.region[j] in _TRUNK_REGIONS and c.bone_length[j] > 1e-9
        ],
        np.int64,
    )
    if not len(idx):
        return idx, np.zeros((0, 3)), np.zeros(0)
    r = TRUNK_SHARE * 0.5 * (c.mass_size[idx, 0] + c.mass_size[idx, 2])
    centre = np.array(c.mass_center[idx], float)
    # a vertebra without mass of its own (its tissue is counted on a neighbour) has no
    # meaningful mass centre: it takes the nearest massive section's offset and radius
    own = (c.mass[idx] > 0) & np.isfinite(centre).all(axis=1)
    if own.any() and not own.all():
        P = c.joint_positions[idx]
        near = np.flatnonzero(own)[
            np.argmin(np.linalg.norm(P[~own][:, None] - P[own][None], axis=2), axis=1)
        ]
        centre[~own] = P[~own] + centre[near] - P[near]
        r[~own] = r[near]
    return idx, centre, r


def _section_frames(c: Creature, js: NDArray, centre: NDArray) -> tuple[NDArray, NDArray, NDArray]:
    """Per vertebra: headward spine tangent ``t``, right ``lat`` (⟂ t) and ``dorsal`` (⟂ both,
    pointing from the section's centre towards the spine)."""
    P = c.joint_positions[js]
    t = c.bone_ends[js] - P
    t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-12)
    head = _headward(c)[js]
    t[~head] *= -1
    z = np.array([0.0, 0.0, 1.0])
    lat = z - (t @ z)[:, None] * t
    lat /= np.maximum(np.linalg.norm(lat, axis=1, keepdims=True), 1e-12)
    dorsal = np.cross(lat, t)
    off = P - centre
    sign = np.where(np.abs((off * dorsal).sum(1)) > 1e-9, (off * dorsal).sum(1), dorsal[:, 1])
    dorsal[sign < 0] *= -1
    return t, lat, dorsal


def _headward(c: Creature) -> NDArray[np.bool_]:
    """Joints whose bone points towards the head: the skull and those of its ancestors
    whose bone runs towards the skull's side of the chain. The root vertebra is the skull's
    ancestor but its bone points to the tail (its local X is dorsal): counting it headward
    turned its vertebra upside down (a box-like centrum above the spine)."""
    out = np.zeros(len(c), bool)
    j = c.kind.index("skull") if "skull" in c.kind else -1
    child = -1
    while j >= 0:
        if child < 0:
            out[j] = True
        else:
            to_child = c.joint_positions[child] - c.joint_positions[j]
            y = c.world[j, :3, 1]
            if float(np.linalg.norm(to_child)) > 0.25 * float(c.bone_length[j]):
                out[j] = float(to_child @ y) >= 0.0
            else:  # the child starts where this bone starts (the root): compare directions
                out[j] = float(c.world[child, :3, 1] @ y) >= 0.0 if out[child] else False
        child, j = j, int(c.skeleton.parent[j])
    return out


def _section_of(c: Creature) -> dict[int, tuple[NDArray, float]]:
    idx, centre, r = trunk_sections(c)
    return {int(j): (centre[k], float(r[k])) for k, j in enumerate(idx)}


def rib_cage(
    c: Creature, thoracic: list[int], lod: int, pleural: bool = False
) -> dict[int, tuple[NDArray, NDArray, NDArray]]:
    """Ribs (and a sternebra for true ribs) per thoracic joint: ``{joint: (vertices (world),
    faces, rib_vertex_mask)}``. ``pleural`` (fish): no sternum, every rib ends free
    ``PLEURAL_REACH`` of the way round the body cavity."""
    sec = _section_of(c)
    js = np.array([j for j in thoracic if j in sec], np.int64)
    if not len(js):
        return {}
    centre = np.array([sec[int(j)][0] for j in js])
    radius = np.array([sec[int(j)][1] for j in js])
    _, all_c, all_r = trunk_sections(c)
    t, lat, dorsal = _section_frames(c, js, centre)
    P = c.joint_positions[js]
    L = c.bone_length[js]
    n = len(js)
    # centre moved into each vertebra's cross plane
    cen = centre - ((centre - P) * t).sum(1, keepdims=True) * t
    rho1 = (1.0 - BODY_WALL) * radius  # the sternum's depth below the centre
    order = np.argsort(np.argsort(-((P - P.mean(0)) * t).sum(1)))  # 0 = most cranial
    true = (order < max(1, int(round(TRUE_RIBS * n)))) & (not pleural)
    reach = PLEURAL_REACH if pleural else FLOATING_REACH
    k = 6 + 3 * lod
    sides = max(4, SIDES[lod] // 2)
    w_half = 0.11 * L  # rib half-width along the spine
    th_half = np.minimum(0.07 * L + 0.02 * radius, 0.25 * BODY_WALL * radius)
    # both ribs of every vertebra at once: arrays (n, 2 sides, k points along the rib)
    la = np.stack([lat, -lat], axis=1)  # (n, 2, 3)
    bz, bx = c.box_size[js, 2], c.box_size[js, 0]
    head = P[:, None] + la * (0.3 * bz)[:, None, None] - (dorsal * (0.15 * bx)[:, None])[:, None]
    rel = head - cen[:, None]
    r_d, r_l = (rel * dorsal[:, None]).sum(2), (rel * la).sum(2)
    rho0, th0 = np.hypot(r_d, r_l), np.arctan2(r_l, r_d)
    th1 = np.pi * np.where(true, 1.0, reach)
    # true ribs stop at the sternum's side
    th1 = th1 - np.where(true, np.arcsin(np.minimum(0.9, 1.6 * w_half / rho1)), 0.0)
    u = np.linspace(0.0, 1.0, k)
    th = th0[..., None] + (th1[:, None, None] - th0[..., None]) * u
    dirs = np.cos(th)[..., None] * dorsal[:, None, None] + np.sin(th)[..., None] * la[:, :, None]
    origin = cen[:, None, None] - (RIB_SLOPE * L[:, None] * u)[:, None, :, None] * t[:, None, None]
    origin = np.broadcast_to(origin, dirs.shape)
    # the trunk's surface along each rib ray (the sections overlap: their union)
    inner = _exit_distance(origin.reshape(-1, 3), dirs.reshape(-1, 3), all_c, all_r)
    inner = inner.reshape(n, 2, k) - (BODY_WALL * radius)[:, None, None]
    # from the rib's head (inside the vertebra's own tissue) straight onto the cage's
    # circle: never outside it, where the skin creases between spine and trunk
    blend = np.clip(u / 0.35, 0, 1)
    blend = blend * blend * (3 - 2 * blend)
    rho = np.minimum(rho0[..., None] * (1 - blend) + inner * blend, inner)
    rho[..., 0] = rho0
    paths = (origin + rho[..., None] * dirs).reshape(2 * n, k, 3)
    r_w = np.repeat(np.broadcast_to(w_half[:, None], (n, k)), 2, axis=0)
    r_t = np.repeat(th_half[:, None] * np.r_[1.3, np.ones(k - 1)], 2, axis=0)
    v, f = tubes(paths, r_w, sides, radius2=r_t, ref=np.repeat(t, 2, axis=0))
    per_v, per_f = 2 * (k * sides + 2), 2 * len(f) // (2 * n)
    # sternebrae below the true ribs' vertebrae
    bottom = cen - dorsal * rho1[:, None] - (RIB_SLOPE * L)[:, None] * t
    st_path = np.stack([bottom + (0.55 * L)[:, None] * t, bottom - (0.55 * L)[:, None] * t], 1)
    sv, sf = tubes(
        st_path,
        np.repeat(1.4 * w_half[:, None], 2, 1),
        sides,
        radius2=np.repeat(th_half[:, None], 2, 1),
        ref=lat,
    )
    st_v, st_f = 2 * sides + 2, len(sf) // n
    out = {}
    for i, j in enumerate(js.tolist()):
        vi = v[i * per_v : (i + 1) * per_v]
        fi = f[i * per_f : (i + 1) * per_f] - i * per_v
        mask = np.ones(len(vi), bool)
        if true[i]:
            svi = sv[i * st_v : (i + 1) * st_v]
            sfi = sf[i * st_f : (i + 1) * st_f] - i * st_v + len(vi)
            fi = np.concatenate([fi, sfi])
            vi = np.concatenate([vi, svi])
            mask = np.r_[mask, np.zeros(len(svi), bool)]
        out[j] = (vi, fi, mask)
    return out


def _exit_distance(origin: NDArray, dirs: NDArray, centre: NDArray, radius: NDArray) -> NDArray:
    """Per ray ``origin (k, 3) + s · dirs (k, 3)``: the farthest ``s`` inside any of the
    spheres (0 where the ray misses them all)."""
    oc = centre[None, :, :] - origin[:, None, :]  # (k, n, 3)
    b = (oc * dirs[:, None, :]).sum(axis=2)
    disc = b * b - (oc * oc).sum(axis=2) + radius[None, :] ** 2
    s = np.where(disc > 0, b + np.sqrt(np.maximum(disc, 0.0)), 0.0)
    return np.maximum(s.max(axis=1), 0.0)


def scapula_frame(c: Creature, j: int, cls: str) -> tuple[NDArray, NDArray, float] | None:
    """The scapula of girdle joint ``j``: its frame (world, columns x across the blade, y
    from the dorsal border to the glenoid, z out of the cage), the dorsal border's middle
    (world) and its length (m): the glenoid at the shoulder joint, the blade rising up and
    back at :data:`SCAPULA_INCLINATION`, its dorsal end laid in the thoracic wall (half way
    between the ribs and the skin), never above the neural spines' tops."""
    par = int(c.skeleton.parent[j])
    sec = _section_of(c)
    kids = np.flatnonzero(c.skeleton.parent == j)
    if par not in sec or not kids.size:
        return None
    centre, r = sec[par]
    t, lat, dorsal = (a[0] for a in _section_frames(c, np.array([par]), centre[None]))
    P = c.joint_positions[par]
    glen = c.bone_ends[j]
    side = 1.0 if (glen - P) @ lat >= 0 else -1.0
    la = side * lat
    humerus = float(c.bone_length[int(kids[0])])
    ls = SCAPULA_LENGTH * max(humerus, float(c.bone_length[j]))
    ang = np.radians(SCAPULA_INCLINATION.get(cls, 58.0))
    top = (P - glen) @ dorsal + 0.45 * c.box_size[par, 0]  # up to the neural spines' tops
    rise = min(ls * np.sin(ang), max(top, 0.0))
    back = ls * np.cos(ang) if rise >= ls * np.sin(ang) else rise / np.tan(ang)
    ls = float(np.hypot(rise, back))
    if ls < 1e-9:
        return None
    d_pt = glen + rise * dorsal - back * t
    # in the thoracic wall: the dorsal end's lateral offset puts it half way between the
    # ribs and the trunk's surface there
    cen = centre - ((centre - P) * t).sum() * t
    up = (d_pt - cen) @ dorsal
    wall = (1.0 - 0.5 * BODY_WALL) * r
    lateral_min = np.sqrt(max(wall**2 - up**2, 0.0))
    lateral_min = max(lateral_min, 0.35 * c.box_size[par, 2])
    cur = (d_pt - cen) @ la
    # the trunk's own surface beside the dorsal end (the union of the sections there, which
    # narrows dorsally): the blade lies on the cage, its dorsal border in the wall. Only
    # pushing outwards left a blade hung from a wide-set shoulder standing clear of the
    # chest (its spinati made a lump on the skin)
    mid = d_pt - cur * la
    _, all_c, all_r = trunk_sections(c)
    exit_ = float(_exit_distance(mid[None], la[None], all_c, all_r)[0])
    if exit_ > 0:
        target = max(exit_ - 0.5 * BODY_WALL * r, 0.35 * c.box_size[par, 2])
        d_pt = d_pt + (target - cur) * la
    elif cur < lateral_min:
        d_pt = d_pt + (lateral_min - cur) * la
    y_ax = glen - d_pt
    y_ax /= np.linalg.norm(y_ax)
    normal = la - (la @ y_ax) * y_ax
    normal /= np.linalg.norm(normal)
    x_ax = np.cross(y_ax, normal)
    return np.stack([x_ax, y_ax, normal], axis=1), d_pt, float(np.linalg.norm(glen - d_pt))


#: the blade's width and thickness as shares of its length (dog and horse scapulae are
#: about half as wide as long)
SCAPULA_WIDTH = 0.55
SCAPULA_THICKNESS = 0.1


def scapula_blade(
    c: Creature, j: int, unit_model: tuple[NDArray, NDArray, NDArray], cls: str
) -> tuple[NDArray, NDArray] | None:
    """The scapula of girdle joint ``j`` in world coordinates: ``unit_model`` (y from the
    dorsal border at 0 to the glenoid at 1, x across the blade, z its thickness) laid in
    :func:`scapula_frame`."""
    fr = scapula_frame(c, j, cls)
    if fr is None:
        return None
    frame, d_pt, ls = fr
    v0, _, f = unit_model
    scale = np.array([SCAPULA_WIDTH * ls, ls, SCAPULA_THICKNESS * ls])
    v = (v0 * scale) @ frame.T + d_pt
    if np.linalg.det(frame) < 0:
        f = f[:, ::-1]
    return v, f
