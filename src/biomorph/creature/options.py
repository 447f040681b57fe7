"""What the user asks of the creature generator: :class:`Options` and its validation.

One options type shared by the Python API (:func:`biomorph.creature.generate`), the CLI
(``biomorph creature generate``), ``creature batch`` and the studio's creature tab.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from biomorph.creature import limbs as lb
from biomorph.creature import pca as pc
from biomorph.creature.dataset import CLASSES
from biomorph.errors import ParameterError

STEPS = ("spine", "girdles", "limbs", "skull", "finish")
LEG_COUNTS = (0, 2, 4, 6)


#: How far (factor) a requested weight may lie outside the dataset's weight range.
EXTRAPOLATION = 10.0

#: Largest |score| (standard deviations) accepted in :attr:`Options.scores`.
MAX_SCORE = 4.0


@dataclass(frozen=True)
class Options:
    """What the user asks for. ``None`` means "sample it".

    legs : legs with ground contact, 0/2/4/6. wings / arms / centaur : limb choices.
    weight : kg. neck_length / tail_length : neck / tail chord in frame units (1.0 = the
    1000-px frame, i.e. the largest extent of the skeleton). cls : animal class.
    k : PCA components to sample from (None = all 29). temperature : variance scale.
    jitter : scale of the jitter interval on conditioned values.
    scores : fixed PCA component scores ``{component index (0-based): score}`` in standard
    deviations of that component (units of ``sqrt(eigenvalue)``, independent of the
    temperature), |score| <= 4; the other components are sampled as without them.
    stand_fraction : the shortest leg stands at this fraction of its straightened reach.
    require_stable : repair or resample until statically stable.
    min_margin_fraction : the least stability margin, a share of the larger of body length
    and centre-of-mass height (:mod:`biomorph.creature.balance`).
    allow_extrapolation : accept a weight more than :data:`EXTRAPOLATION` × outside the
    dataset's weight range (the PCA was fitted on 0.01 kg … 120 t animals).
    hoof_digits : hoofed digits per foot, 1 (perissodactyl: horse) or 2 (artiodactyl:
    cattle, deer); makes the creature a hoofed (unguligrade) mammal. ``None``: inherited from
    the nearest unguligrade species (the body plan), 0 for other feet.
    """

    seed: int = 0
    legs: int | None = None
    wings: bool | None = None
    arms: bool = False
    centaur: bool = False
    weight: float | None = None
    neck_length: float | None = None
    tail_length: float | None = None
    cls: str | None = None
    k: int | None = None
    temperature: float = 1.0
    jitter: float = 1.0
    descent: lb.DescentParams = field(default_factory=lb.DescentParams)
    stand_fraction: float = 0.8
    require_stable: bool = True
    min_margin_fraction: float = 0.02
    max_resamples: int = 25
    dataset: str | None = None
    scores: dict[int, float] | None = None
    allow_extrapolation: bool = False
    hoof_digits: int | None = None

    def __post_init__(self) -> None:
        # own copy: later changes to the caller's dict do not leak into the options
        if self.scores is not None:
            object.__setattr__(self, "scores", dict(self.scores))

    def validate(self) -> Options:
        """Raise :class:`ParameterError` for impossible requests; return self."""
        if self.scores is not None:
            n = pc.N_DIMS if self.k is None else int(self.k)
            for idx, val in self.scores.items():
                if (
                    isinstance(idx, bool)
                    or not isinstance(idx, (int, np.integer))
                    or not 0 <= idx < n
                ):
                    raise ParameterError(
                        f"PCA component {idx!r}: expected an index 0..{n - 1} "
                        f"(the model's {n} sampled components)"
                    )
                try:
                    v = float(val)
                except (TypeError, ValueError):
                    v = float("nan")
                if not (np.isfinite(v) and abs(v) <= MAX_SCORE):
                    raise ParameterError(
                        f"PCA component {idx} score {val!r}: expected a finite "
                        f"score in -{MAX_SCORE:g}..{MAX_SCORE:g} standard "
                        "deviations"
                    )
        if self.legs is not None and self.legs not in LEG_COUNTS:
            raise ParameterError(
                f"legs={self.legs}: legs come in pairs with ground contact; expected 0, 2, 4 or 6"
            )
        if self.weight is not None and not (np.isfinite(self.weight) and self.weight > 0):
            raise ParameterError(f"weight={self.weight} kg: expected a positive weight in kg")
        if self.weight is not None and not self.allow_extrapolation:
            from biomorph.creature.model import species_model

            w = species_model(self.dataset).table.weight
            lo, hi = float(w.min()) / EXTRAPOLATION, float(w.max()) * EXTRAPOLATION
            if not lo <= self.weight <= hi:
                raise ParameterError(
                    f"weight={self.weight:g} kg is more than {EXTRAPOLATION:g}× outside the "
                    f"dataset's range {w.min():g}..{w.max():g} kg; expected {lo:g}..{hi:g} kg "
                    "or --allow-extrapolation"
                )
        if self.cls is not None and self.cls not in CLASSES:
            raise ParameterError(
                f"class {self.cls!r} unknown; expected one of {', '.join(CLASSES)}"
            )
        for name in ("neck_length", "tail_length"):
            v = getattr(self, name)
            if v is not None and not (np.isfinite(v) and 0 <= v <= 1.5):
                raise ParameterError(
                    f"{name.replace('_', '-')}={v}: expected 0..1.5 frame "
                    "units (1 = the skeleton's largest extent)"
                )
        if self.cls == "fish":
            if self.wings:
                raise ParameterError(
                    "wings need a shoulder joint (scapula with a wing socket); "
                    "class fish has only fin girdles"
                )
            if self.legs:
                raise ParameterError(
                    f"legs={self.legs} with class fish: fish have fins, no legs with ground contact"
                )
            if self.arms or self.centaur:
                raise ParameterError(
                    "arms/centaur need a tetrapod shoulder; class fish has only fin girdles"
                )
        if self.legs == 6 and self.wings and self.arms:
            raise ParameterError(
                "six legs, wings and arms need three shoulder limb pairs; a "
                "girdle holds at most two"
            )
        if self.legs == 6 and (self.wings or self.arms) and not self.centaur:
            raise ParameterError(
                "six legs fill the shoulder girdle (two leg pairs); wings or "
                "arms need a free shoulder slot (use --centaur for arms)"
            )
        if self.hoof_digits is not None:
            if isinstance(self.hoof_digits, bool) or self.hoof_digits not in (1, 2):
                raise ParameterError(
                    f"hoof_digits={self.hoof_digits!r}: expected 1 (perissodactyl: horse) or "
                    "2 (artiodactyl: cattle, deer)"
                )
            if self.cls is not None and self.cls != "mammal":
                raise ParameterError(
                    f"hoof_digits with class {self.cls}: hooves are the feet of ungulate "
                    "mammals; drop --class or ask for --class mammal"
                )
            if self.legs == 0:
                raise ParameterError("hoof_digits with --legs 0: hooves need legs to stand on")
        if not 0 < self.stand_fraction <= 1:
            raise ParameterError(f"stand_fraction={self.stand_fraction}: expected 0 < f <= 1")
        if self.temperature < 0 or self.jitter < 0:
            raise ParameterError("temperature and jitter must be >= 0")
        return self
