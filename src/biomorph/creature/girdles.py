"""Girdles and the rules that decide which limbs attach where (seed §5.2).

A girdle sits on the spine: the shoulder girdle at the neck/back join, the hip girdle at the
back/tail join, and optionally a centaur-like extra shoulder girdle on the neck just below the
head. Each girdle holds up to two limb pairs (joints a little apart along the spine). Arms and
wings attach only at shoulder girdles, legs and fins at shoulder and hip; the centaur girdle
takes anything but legs.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from biomorph.errors import ParameterError

GIRDLES = ("shoulder", "hip", "centaur")
ALLOWED = {
    "shoulder": ("leg", "arm", "wing", "fin"),
    "hip": ("leg", "fin"),
    "centaur": ("arm", "wing", "fin"),
}
MAX_PAIRS = 2
#: A centaur girdle needs a neck at least this long relative to the back chord.
CENTAUR_MIN_NECK = 0.55


@dataclass(frozen=True)
class LimbSpec:
    """One limb pair: type and its three segment lengths (frame px)."""

    kind: str
    lengths: tuple[float, float, float]


@dataclass(frozen=True)
class Girdle:
    """A girdle: where on the spine (arc length from the head end, frame px) and its pairs."""

    name: str
    at: float
    pairs: tuple[LimbSpec, ...] = ()

    def with_pair(self, spec: LimbSpec) -> Girdle:
        check_pair(self.name, spec.kind, len(self.pairs) + 1)
        return replace(self, pairs=self.pairs + (spec,))


def check_pair(girdle: str, kind: str, n_pairs: int) -> None:
    """Raise :class:`ParameterError` if ``kind`` cannot be the ``n_pairs``-th pair there."""
    if girdle not in ALLOWED:
        raise ParameterError(f"girdle {girdle!r} unknown; expected one of {', '.join(GIRDLES)}")
    if kind not in ALLOWED[girdle]:
        raise ParameterError(
            f"a {kind} cannot attach at the {girdle} girdle; allowed there: "
            f"{', '.join(ALLOWED[girdle])}"
        )
    if n_pairs > MAX_PAIRS:
        raise ParameterError(
            f"the {girdle} girdle already holds {MAX_PAIRS} limb pairs; "
            f"no room for another {kind} pair"
        )


def plan(
    cls: str,
    legs: int,
    wings: bool,
    arms: bool,
    centaur: bool,
    fore: np.ndarray,
    hind: np.ndarray,
    region_len: np.ndarray,
) -> tuple[Girdle, ...]:
    """Decide girdles and limb pairs from the discrete choices (lengths in frame px).

    ``legs`` in 0/2/4/6; ``fore``/``hind`` are the sampled (upper, lower, distal) lengths.
    """
    neck, back, _ = region_len
    s_sh, s_hip = neck, neck + back
    fore_t = tuple(float(v) for v in fore)
    hind_t = tuple(float(v) for v in hind)
    shoulder: list[LimbSpec] = []
    hip: list[LimbSpec] = []
    has_fore = sum(fore_t) > 1e-6
    has_hind = sum(hind_t) > 1e-6
    if legs >= 4:
        shoulder.append(LimbSpec("leg", fore_t))
        hip.append(LimbSpec("leg", hind_t))
        if legs == 6:
            shoulder.append(LimbSpec("leg", tuple(0.97 * v for v in fore_t)))
    elif legs == 2:
        hip.append(LimbSpec("leg", hind_t))
    elif has_hind and cls != "bird":
        hip.append(LimbSpec("fin", hind_t))
    if wings:
        shoulder.append(LimbSpec("wing", tuple(1.15 * v for v in fore_t)))
    if legs < 4 and not wings and has_fore:
        kind = "arm" if (legs == 2 and cls != "fish") else "fin"
        shoulder.append(LimbSpec(kind, fore_t))
    if arms and not any(p.kind == "arm" for p in shoulder) and not centaur:
        shoulder.append(LimbSpec("arm", tuple(0.85 * v for v in fore_t)))
    for k, spec in enumerate(shoulder):
        check_pair("shoulder", spec.kind, k + 1)
    out = [Girdle("shoulder", s_sh, tuple(shoulder)), Girdle("hip", s_hip, tuple(hip))]
    if centaur:
        if neck < CENTAUR_MIN_NECK * max(back, 1e-9):
            raise ParameterError(
                f"a centaur girdle needs a neck at least {CENTAUR_MIN_NECK:.2f}"
                f" × the back length; this neck is {neck / max(back, 1e-9):.2f}"
            )
        out.append(
            Girdle("centaur", 0.22 * neck, (LimbSpec("arm", tuple(0.9 * v for v in fore_t)),))
        )
    return tuple(g for g in out if g.pairs)
