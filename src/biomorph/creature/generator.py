"""Stepwise creature generation: spine → girdles → limbs → skull → finish (seed §3.4, §5).

:class:`Generator` runs the steps one at a time; every step can be undone, re-rolled with
another seed or edited, and later steps are re-run so rules propagate (a changed leg is
grounded again; a centaur girdle lengthens a short neck; impossible edits raise
:class:`~biomorph.errors.ParameterError` naming the reason). Each step draws from its own
random stream derived from ``(seed, step, re-roll count)``, so the same seed and options give
the identical creature, and re-rolling one step leaves the others' randomness unchanged.

Units: the first four steps work in the seed's frame units (px of the 1000-px annotation
frame, creature coordinates: x forward, y up, z right); ``finish`` sizes the creature from its
weight (:mod:`biomorph.creature.mass`) and returns metres with the ground at ``y = 0``.

The pieces live in their own modules: :mod:`~biomorph.creature.options` (what the user
asks), :mod:`~biomorph.creature.model` (the cached, read-only species PCA),
:mod:`~biomorph.creature.states` (typed step states), :mod:`~biomorph.creature.steps`
(spine, girdles, limbs, skull), :mod:`~biomorph.creature.assembly` (joint arrays →
:class:`Creature`) and :mod:`~biomorph.creature.repair` (balance repair, ``finish``); this
module is the :class:`Generator` driver with undo, re-roll and edits.
"""

from __future__ import annotations

from dataclasses import replace
from types import MappingProxyType
from typing import Any

import numpy as np

from biomorph.creature import girdles as gd
from biomorph.creature import spine as sp
from biomorph.creature.creature import Creature
from biomorph.creature.dataset import CLASSES
from biomorph.creature.model import species_model
from biomorph.creature.options import LEG_COUNTS, MAX_SCORE, STEPS, Options
from biomorph.creature.repair import finish
from biomorph.creature.states import SpineState, step_rng
from biomorph.creature.steps import step_girdles, step_limbs, step_skull, step_spine
from biomorph.errors import InputError, ParameterError

__all__ = [
    "Generator",
    "Options",
    "generate",
    "STEPS",
    "LEG_COUNTS",
    "MAX_SCORE",
    "CLASSES",
    "species_model",
]


def _model(dataset: str | None) -> MappingProxyType:
    """The species model as a read-only mapping (older callers; prefer
    :func:`~biomorph.creature.model.species_model`)."""
    m = species_model(dataset)
    return MappingProxyType({k: getattr(m, k) for k in m.__dataclass_fields__})


# --------------------------------------------------------------------------- Generator
class Generator:
    """Step-by-step creature generation with undo, re-roll, edits and rule propagation.

    Example
    -------
    >>> g = Generator(Options(seed=3, legs=4))
    >>> g.step()
    'spine'
    >>> g.step()
    'girdles'
    >>> g.set_limb("hip", 0, "fin")   # doctest: +SKIP
    >>> c = g.run()                   # remaining steps -> Creature
    """

    def __init__(self, options: Options | None = None, **kwargs: Any) -> None:
        opts = options if options is not None else Options(**kwargs)
        if options is not None and kwargs:
            opts = replace(opts, **kwargs)
        self.options = opts.validate()
        self._states: dict[str, Any] = {}
        self._rolls = {s: 0 for s in STEPS}
        self._history: list[tuple[dict, dict]] = []
        self._attempt = 0
        self._edits: dict[str, Any] = {}

    # ------------------------------------------------------------ introspection
    @property
    def done(self) -> tuple[str, ...]:
        return tuple(s for s in STEPS if s in self._states)

    @property
    def next_step(self) -> str | None:
        for s in STEPS:
            if s not in self._states:
                return s
        return None

    def state(self, step: str) -> Any:
        if step not in self._states:
            raise ParameterError(f"step {step!r} has not run yet; done: {', '.join(self.done)}")
        return self._states[step]

    @property
    def creature(self) -> Creature:
        return self.state("finish")

    # ------------------------------------------------------------ running
    def _seed_rng(self, step: str) -> np.random.Generator:
        return step_rng(self.options.seed + 7919 * self._attempt, step, self._rolls[step])

    def _run(self, step: str) -> None:
        o = self.options
        st = self._states
        if step == "spine":
            spine = step_spine(o, self._seed_rng("spine"))
            for k, v in self._edits.get("spine", {}).items():
                spine = _apply_spine_edit(spine, k, v)
            st["spine"] = spine
        elif step == "girdles":
            g = step_girdles(st["spine"], o, self._seed_rng("girdles"))
            for edit in self._edits.get("girdles", []):
                g = _apply_girdle_edit(g, edit, st["spine"])
            st["girdles"] = g
        elif step == "limbs":
            st["limbs"] = step_limbs(st["spine"], st["girdles"], o, self._seed_rng("limbs"))
        elif step == "skull":
            st["skull"] = step_skull(st["spine"], st["limbs"], o, self._seed_rng("skull"))
        else:
            st["finish"] = finish(
                st["spine"],
                st["girdles"],
                st["limbs"],
                st["skull"],
                o,
                self._seed_rng("finish"),
                {"resamples": self._attempt},
            )

    def _snapshot(self) -> None:
        self._history.append(
            (
                dict(self._states),
                {
                    "rolls": dict(self._rolls),
                    "edits": _copy_edits(self._edits),
                    "attempt": self._attempt,
                },
            )
        )

    def step(self) -> str:
        """Run the next step; return its name."""
        s = self.next_step
        if s is None:
            raise ParameterError("all steps have run; undo or edit first")
        self._snapshot()
        self._run(s)
        return s

    def run(self) -> Creature:
        """Run all remaining steps; with ``require_stable`` resample until balanced."""
        while self.next_step is not None:
            self.step()
        c = self.creature
        o = self.options
        while o.require_stable and self._attempt < o.max_resamples and _needs_resample(c):
            self._attempt += 1
            self._states.clear()
            while self.next_step is not None:
                self._run(self.next_step)
            c = self.creature
        if (
            o.require_stable
            and c.balance is not None
            and c.balance.applicable
            and not c.balance.stable
        ):
            raise InputError(
                f"no statically stable creature found for seed {o.seed} after "
                f"{o.max_resamples} resamples; relax the conditions or pass "
                "require_stable=False"
            )
        return c

    def undo(self) -> str:
        """Undo the last step or edit; return what is now the next step."""
        if not self._history:
            raise ParameterError("nothing to undo")
        states, meta = self._history.pop()
        self._states = states
        self._rolls = meta["rolls"]
        self._edits = meta["edits"]
        self._attempt = meta["attempt"]
        return self.next_step or "done"

    def _invalidate_from(self, step: str) -> list[str]:
        i = STEPS.index(step)
        redo = [s for s in STEPS[i:] if s in self._states]
        for s in STEPS[i:]:
            self._states.pop(s, None)
        return redo

    def _rerun(self, steps: list[str]) -> None:
        for s in STEPS:
            if s in steps:
                self._run(s)

    def reroll(self, step: str, seed: int | None = None) -> None:
        """Re-run ``step`` with fresh randomness (or the stream of ``seed``), then re-run the
        later steps that had already run (rule propagation)."""
        if step not in STEPS:
            raise ParameterError(f"step {step!r} unknown; expected one of {', '.join(STEPS)}")
        if step not in self._states:
            raise ParameterError(f"step {step!r} has not run yet")
        self._snapshot()
        self._rolls[step] = (self._rolls[step] + 1) if seed is None else 1000 + int(seed)
        self._rerun(self._invalidate_from(step))

    # ------------------------------------------------------------ edits
    def _edit(self, step: str, record) -> None:
        if step not in self._states:
            raise ParameterError(f"run the {step} step before editing it")
        self._snapshot()
        try:
            record()
            self._rerun(self._invalidate_from(step))
        except Exception:
            self.undo()
            raise

    def set_limb(self, girdle: str, pair: int, kind: str) -> None:
        """Change the type of limb pair ``pair`` (0-based) at ``girdle``."""
        self._check_girdle_pair(girdle, pair)
        gd.check_pair(girdle, kind, pair + 1)
        if (
            kind == "leg"
            and girdle == "shoulder"
            and not any(
                p.kind == "leg" for g in self.state("girdles") if g.name == "hip" for p in g.pairs
            )
        ):
            raise ParameterError(
                "legs at the shoulder need legs at the hip too: a creature "
                "cannot stand on its front legs alone"
            )
        self._edit(
            "girdles",
            lambda: self._edits.setdefault("girdles", []).append(("set", girdle, pair, kind)),
        )

    def add_limb_pair(self, girdle: str, kind: str) -> None:
        """Add a limb pair of ``kind`` at ``girdle`` (at most two pairs per girdle)."""
        if girdle == "centaur":
            sp_ = self.state("spine")
            xy, s, region = sp.sample(sp_.points)
            rl = sp.region_lengths(s, region)
            if rl[0] < gd.CENTAUR_MIN_NECK * rl[1]:
                raise ParameterError(
                    f"a centaur girdle needs a neck of at least "
                    f"{gd.CENTAUR_MIN_NECK:.2f} × the back; lengthen the neck "
                    "first (set_neck_length)"
                )
        existing = [g for g in self.state("girdles") if g.name == girdle]
        n = len(existing[0].pairs) if existing else 0
        gd.check_pair(girdle, kind, n + 1)
        self._edit(
            "girdles",
            lambda: self._edits.setdefault("girdles", []).append(("add", girdle, None, kind)),
        )

    def set_neck_length(self, factor: float) -> None:
        """Scale the neck chord by ``factor`` (0 < factor <= 4); later steps re-run."""
        if not (np.isfinite(factor) and 0 < factor <= 4):
            raise ParameterError(f"neck factor {factor}: expected 0 < factor <= 4")
        self._edit(
            "spine",
            lambda: self._edits.setdefault("spine", {}).__setitem__(
                "neck", self._edits.get("spine", {}).get("neck", 1.0) * factor
            ),
        )

    def set_tail_length(self, factor: float) -> None:
        """Scale the tail chord by ``factor`` (0 < factor <= 4)."""
        if not (np.isfinite(factor) and 0 < factor <= 4):
            raise ParameterError(f"tail factor {factor}: expected 0 < factor <= 4")
        self._edit(
            "spine",
            lambda: self._edits.setdefault("spine", {}).__setitem__(
                "tail", self._edits.get("spine", {}).get("tail", 1.0) * factor
            ),
        )

    def _check_girdle_pair(self, girdle: str, pair: int) -> None:
        gs = {g.name: g for g in self.state("girdles")}
        if girdle not in gs:
            raise ParameterError(f"no {girdle} girdle on this creature; girdles: {', '.join(gs)}")
        if not 0 <= pair < len(gs[girdle].pairs):
            raise ParameterError(
                f"the {girdle} girdle has {len(gs[girdle].pairs)} limb "
                f"pair(s); pair {pair} does not exist"
            )


def _needs_resample(c: Creature) -> bool:
    """Below the ground, unstable, or breaking the femur, knee/elbow or withers rule
    (``params["anatomy_rules"]``, :func:`biomorph.creature.quality.rules_hold`): the
    generator meets those rules by construction and resamples the rare draw it cannot
    repair (a back too short to keep the hind knees behind the elbows, legs too heavy for
    their height)."""
    if c.params.get("below_ground") or c.params.get("anatomy_rules") is False:
        return True
    return bool(c.balance is not None and c.balance.applicable and not c.balance.stable)


def _copy_edits(e: dict) -> dict:
    return {k: (list(v) if isinstance(v, list) else dict(v)) for k, v in e.items()}


def _apply_spine_edit(spine: SpineState, key: str, factor: float) -> SpineState:
    pts = np.array(spine.points, float)
    if key == "neck":
        pts[0:3] = pts[3] + (pts[0:3] - pts[3]) * factor
    else:
        pts[7:10] = pts[6] + (pts[7:10] - pts[6]) * factor
    return replace(spine, points=sp.c1_fix(pts))


def _apply_girdle_edit(girdles, edit, spine) -> tuple:
    op, name, pair, kind = edit
    out = list(girdles)
    names = [g.name for g in out]
    if op == "set":
        g = out[names.index(name)]
        old = g.pairs[pair]
        pairs = list(g.pairs)
        pairs[pair] = gd.LimbSpec(kind, old.lengths)
        out[names.index(name)] = replace(g, pairs=tuple(pairs))
    else:
        xy, s, region = sp.sample(spine.points)
        rl = sp.region_lengths(s, region)
        L = np.asarray(spine.lengths, float)
        back = max(rl[1], 0.05 * s[-1])
        base = L[:3] if name in ("shoulder", "centaur") else L[3:]
        lengths = tuple(float(v) for v in np.maximum(base, 0.08 * back))
        if name in names:
            out[names.index(name)] = out[names.index(name)].with_pair(gd.LimbSpec(kind, lengths))
        else:
            at = {"shoulder": rl[0], "hip": rl[0] + rl[1], "centaur": 0.22 * rl[0]}[name]
            out.append(gd.Girdle(name, at, (gd.LimbSpec(kind, lengths),)))
    return tuple(out)


def generate(seed: int = 0, **kwargs: Any) -> Creature:
    """Generate one creature (all steps). Keyword arguments are :class:`Options` fields;
    ``cls`` may also be given as ``class_``."""
    if "class_" in kwargs:
        kwargs["cls"] = kwargs.pop("class_")
    return Generator(Options(seed=seed, **kwargs)).run()
