"""Typed options of the tree pipeline: one dataclass per stage, one umbrella.

:func:`biomorph.tree.skeletonize` runs six stages; each reads exactly one of these:

=================  ======================  ==================================================
stage              options                 runs
=================  ======================  ==================================================
prepare            :class:`PrepareOptions`  centring, attribute filter, downsampling, outliers,
                                            ground, foliage and clutter removal
graph              :class:`GraphOptions`    Livny et al. (2010), :mod:`~biomorph.tree.livny`
voxel              :class:`VoxelOptions`    Gorte & Pfeifer (2004), :mod:`~biomorph.tree.voxel`
cleanup            :class:`CleanupOptions`  false branches, overlap collapse, tip support
radius             :class:`RadiusOptions`   circle fits, taper model, smoothing
order              :class:`OrderOptions`    trunk and branch order (:mod:`~biomorph.tree.order`)
=================  ======================  ==================================================

:class:`SkeletonizeOptions` holds one of each plus ``method`` and ``seed``. The same object
is built by the Python API (``SkeletonizeOptions(graph=GraphOptions(k=12))`` or
:meth:`SkeletonizeOptions.from_kwargs` for the old flat keywords), by the CLI (every field
with a ``cli`` entry in its metadata becomes an option of ``biomorph tree skeletonize`` *and*
``biomorph tree batch``, see :func:`cli_fields` / :meth:`SkeletonizeOptions.from_cli`), by the
batch workers (the dataclass pickles) and by the studio.

Pure dataclasses and the standard library only: the CLI imports this module at start-up,
so it must not load numpy. Angles are radians here, degrees on the command line.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

from biomorph.errors import ParameterError

__all__ = [
    "AttributeFilter",
    "CleanupOptions",
    "CliField",
    "GraphOptions",
    "OrderOptions",
    "PrepareOptions",
    "RadiusOptions",
    "SkeletonizeOptions",
    "VoxelOptions",
    "STAGES",
    "METHODS",
    "UNITS",
    "UP_AXES",
    "cli_default",
    "cli_fields",
    "cli_type",
    "TIP_LENGTH",
    "MIN_CYLINDER_RADIUS",
    "TIP_SUPPORT_LENGTH",
]

METHODS = ("graph", "voxel")
#: default shortest side tip kept by the graph method's cleanup, in node spacings: shorter
#: tips are range-noise spurs or foliage remnants. Measured on the synthetic presets (clean
#: and noisy leafy scans at 60,000 points, foliage separation, chain smoothing): NOB 93–109 %
#: of the truth at 3 (median of two seeds); 1.5 gave up to 159 % (bench/tree.py, docs/tree.md)
TIP_LENGTH = 3.0
#: default floor (m) of the cylinder radius in the fork rule of the overlap collapse: two
#: branches whose axes run within 1 cm of each other are one branch seen through range noise
#: (240,000 points, 8 mm noise, leaf clutter: leafy maple NOB 188 → 130 %; docs/tree.md
#: "Denser scans").
MIN_CYLINDER_RADIUS = 0.01
#: ``tip_support`` only judges tip chains shorter than this many node spacings: long chains
#: are real branches however sparsely the scan sampled them
TIP_SUPPORT_LENGTH = 8.0


@dataclass(frozen=True)
class CliField:
    """How one option field appears on the command line.

    ``flag``: the option name; ``help``; ``lo``/``hi`` (``lo_open``/``hi_open``) the accepted
    range checked at parse time; ``kind`` a conversion between the CLI value and the field:
    ``"degrees"`` (CLI degrees → radians), ``"ground"`` (bool → ``"auto"``/None),
    ``"foliage"`` (None → ``"auto"``, 0 → off), ``"filter"`` (``NAME:MAX`` or
    ``NAME:MIN:MAX`` → :class:`AttributeFilter`), ``"enabled"`` (plain bool).
    ``short``: an optional one-letter alias.
    """

    flag: str
    help: str
    lo: float | None = None
    hi: float | None = None
    lo_open: bool = False
    hi_open: bool = False
    kind: str | None = None
    short: str | None = None


def _opt(default: Any, flag: str, help: str, **cli: Any) -> Any:
    return field(default=default, metadata={"cli": CliField(flag, help, **cli)})


#: metres per unit of a cloud's coordinates (``PrepareOptions.units``, ``--units``;
#: :func:`biomorph.tree.cloud.to_metres`)
UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001, "ft": 0.3048}

#: the axis a cloud's coordinates point up along (``PrepareOptions.up``, ``--up``;
#: :func:`biomorph.tree.cloud.to_z_up`): the tree pillar works Z-up (LAS, TreeQSM), and a
#: Y-up export (glTF-style PLY / OBJ, photogrammetry and game tools) is turned so
UP_AXES = ("z", "y")


@dataclass(frozen=True)
class AttributeFilter:
    """Keep points whose attribute ``name`` lies in ``[min_value, max_value]`` (either bound
    may be None), e.g. the LAS ``Deviation`` attribute."""

    name: str
    max_value: float | None = None
    min_value: float | None = None

    @classmethod
    def parse(cls, spec: str) -> AttributeFilter:
        """``NAME:MAX`` or ``NAME:MIN:MAX`` (an empty bound is open)."""
        parts = spec.split(":")
        if len(parts) not in (2, 3) or not parts[0]:
            raise ParameterError(f"--filter {spec!r}: expected NAME:MAX or NAME:MIN:MAX")
        try:
            if len(parts) == 2:
                return cls(parts[0], max_value=float(parts[1]))
            return cls(
                parts[0],
                min_value=float(parts[1]) if parts[1] else None,
                max_value=float(parts[2]) if parts[2] else None,
            )
        except ValueError:
            raise ParameterError(f"--filter {spec!r}: bounds must be numbers") from None

    def as_kwargs(self) -> dict[str, Any]:
        """Keyword arguments of :func:`biomorph.tree.cloud.filter_attribute`."""
        out: dict[str, Any] = {"name": self.name}
        if self.min_value is not None:
            out["min_value"] = self.min_value
        if self.max_value is not None or self.min_value is None:
            out["max_value"] = self.max_value
        return out


@dataclass(frozen=True)
class PrepareOptions:
    """Cloud preparation (:func:`biomorph.tree.cloud.prepare`, foliage, clutter)."""

    centre: bool = True
    filter: AttributeFilter | None = _opt(
        None,
        "--filter",
        "Keep points with attribute NAME <= MAX (NAME:MAX or NAME:MIN:MAX).",
        kind="filter",
    )
    downsample: float | None = _opt(
        None, "--downsample", "Random downsampling ratio.", lo=0, hi=1, lo_open=True
    )
    downsample_voxel: float | None = _opt(
        None,
        "--downsample-voxel",
        "Keep one random point per cube of this edge, m.",
        lo=0,
        lo_open=True,
    )
    units: str | None = _opt(
        None,
        "--units",
        "Units of the cloud's coordinates: m, cm, mm or ft; every output is in metres "
        "(default: metres, and a cloud taller than any tree, 200 m, stops with a message "
        "naming the units it looks like; tree.cloud.check_units).",
    )
    up: str | None = _opt(
        None,
        "--up",
        "Axis the cloud's coordinates point up along: z (default) or y (a Y-up export: "
        "glTF-style PLY / OBJ, photogrammetry tools); a Y-up cloud is turned Z-up, "
        "(x, y, z) -> (x, -z, y), and every output is in that Z-up frame.",
    )
    outliers: bool = _opt(True, "--outliers", "Statistical outlier removal.", kind="enabled")
    memory_check: bool = _opt(
        True,
        "--memory-check",
        "Stop with a clear message when the cloud needs more memory than "
        "is available (0.25 GB + 600 bytes per point, measured; tree.memory) instead of "
        "being killed by the system, and say how far to thin it.",
        kind="enabled",
    )
    outlier_k: int = 16
    outlier_std: float = 2.0
    ground: str | None = _opt(
        "auto",
        "--ground",
        "Remove the ground: the file's own ground class (LAS class 2) where it has one, "
        "else the ground surface when one is detected (tree.ground).",
        kind="ground",
    )
    foliage: float | str | None = _opt(
        "auto",
        "--foliage",
        "Leaf/wood separation: drop points whose neighbourhood is "
        "thicker than FOLIAGE x the median; 0 = off (default: 3 when foliage is detected "
        "(graph), off (voxel)).",
        kind="foliage",
    )
    foliage_passes: int = 2
    sparse_filter: float | None = _opt(
        None,
        "--clutter",
        "Drop sparse points (leaf clutter): mean 16-NN distance > CLUTTER x median, e.g. 4.",
        lo=1,
        lo_open=True,
    )

    def downsample_arg(self) -> dict[str, Any] | float | None:
        """The ``downsample`` argument of :func:`~biomorph.tree.cloud.prepare`."""
        if self.downsample_voxel is not None:
            kw: dict[str, Any] = {"method": "voxel", "voxel_size": self.downsample_voxel}
            if self.downsample is not None:
                kw["ratio"] = self.downsample
            return kw
        return self.downsample

    def outliers_arg(self) -> bool | dict[str, Any]:
        """The ``outliers`` argument of :func:`~biomorph.tree.cloud.prepare`."""
        if not self.outliers:
            return False
        if (self.outlier_k, self.outlier_std) == (16, 2.0):
            return True
        return {"k": self.outlier_k, "std_ratio": self.outlier_std}


@dataclass(frozen=True)
class GraphOptions:
    """Graph method (:func:`biomorph.tree.livny.skeletonize_graph`); None = from the data."""

    n_trees: int | None = _opt(
        None, "--n-trees", "Number of trees (default: found automatically).", lo=1
    )
    k: int = _opt(10, "--k", "Neighbours per point (graph method).", lo=2)
    search_radius: float | None = _opt(
        None,
        "--search-radius",
        "Neighbour search radius, m (default from the data).",
        lo=0,
        lo_open=True,
    )
    node_spacing: float | None = _opt(
        None,
        "--node-spacing",
        "Skeleton node spacing, m (default from the data).",
        lo=0,
        lo_open=True,
    )
    max_iter: int = _opt(5, "--max-iter", "Re-weighting iterations cap.", lo=0)
    reweight: float = 0.5
    root_slice: float = _opt(
        0.5, "--root-slice", "Height of the slice searched for stem bases, m.", lo=0, lo_open=True
    )
    min_tree_distance: float = _opt(
        0.6, "--min-tree-distance", "Stem bases closer than this are one tree, m.", lo=0
    )
    allometry_exponent: float = 2.5
    edge_weights: str = _opt(
        "livny", "--edge-weights", "Weights of Livny steps iv-v: livny (the paper's) or branch."
    )
    crown_partition: bool = _opt(
        True,
        "--crown-partition",
        "Plots: pieces reached across a gap go to the stem they continue and stand over "
        "(tree/crowns.py); off = Livny's segmentation alone.",
        kind="enabled",
    )


@dataclass(frozen=True)
class VoxelOptions:
    """Voxel method (:func:`biomorph.tree.voxel.skeletonize_voxel`); None = its default."""

    cell_size: float | None = _opt(
        None, "--cell-size", "Voxel size, m (voxel method).", lo=0, lo_open=True
    )
    min_points: int | None = None
    closing_radius: float | None = None
    keep_largest: int | None = None
    bridge_gap: float | None = None
    prune_length: float | None = None
    smooth_iterations: int | None = None
    disc_enclosed: bool = _opt(
        True,
        "--disc-enclosed",
        "Voxel method: fill hollow stems with the disc closing only where the slice "
        "encloses the voxel (a stem's ring), not between crown branches side by side "
        "(TreeLS spruce: 25 -> 6 % of the wood points > 10 cm from every cylinder); "
        "--no-disc-enclosed: the thesis's closing everywhere.",
        kind="enabled",
    )

    def as_kwargs(self) -> dict[str, Any]:
        """The keyword arguments that differ from ``skeletonize_voxel``'s defaults."""
        return {
            f.name: getattr(self, f.name)
            for f in dataclasses.fields(self)
            if getattr(self, f.name) is not None and getattr(self, f.name) != f.default
        }


@dataclass(frozen=True)
class CleanupOptions:
    """Skeleton cleanup (:func:`biomorph.tree.cleanup.cleanup`)."""

    enabled: bool = _opt(
        True, "--cleanup", "False-branch removal and overlap collapse.", kind="enabled"
    )
    radius_ratio: float = 0.5
    length_factor: float = 3.0
    overlap: float = 0.5
    min_branch_length: float | None = _opt(
        None,
        "--min-branch-length",
        "Shortest side tip kept, m (default 3 node spacings "
        "for the graph method, 1.5 voxels for the voxel method).",
        lo=0,
    )
    min_cylinder_radius: float = MIN_CYLINDER_RADIUS
    tip_support: float | None = _opt(
        None,
        "--tip-support",
        "Prune short tip chains with fewer points per node than "
        "TIP_SUPPORT x the median tip chain, e.g. 0.3 for dense leafy scans (graph).",
        lo=0,
        hi=1,
        lo_open=True,
        hi_open=True,
    )
    residual: bool = _opt(
        True,
        "--residual",
        "Grow the skeleton into pieces of wood no cylinder explains "
        "(points more than a node spacing outside every surface, touching the model; "
        "tree.residual), then fit radii again.",
        kind="enabled",
    )
    residual_threshold: float | None = _opt(
        None,
        "--residual-threshold",
        "Residual branches: points farther than this many node spacings outside every "
        "surface are unexplained, and a shoot must reach as far again beyond them "
        "(tree.residual). Default (auto): 0.5 where the points about the twigs form a "
        "surface (the twig offset's test), at least 6 x the scan's scatter, else 1 "
        "(needles and leaves form an envelope whose tufts would become shoots); rTwig F1 "
        "vs TreeQSM 0.976 -> 0.984 (docs/tree.md, sessions 28-29).",
        lo=0,
        lo_open=True,
    )
    empty_tips: bool = _opt(
        True,
        "--empty-tips",
        "Prune short side tip chains whose nodes mostly have no point within 3 point "
        "spacings (strung through leaf clutter or range noise; tree.cleanup."
        "prune_empty_tips), then fit radii again (graph).",
        kind="enabled",
    )
    inside_wood: bool = _opt(
        True,
        "--inside-wood",
        "Prune side branches lying (90 % of their length) inside a branch at least twice "
        "as thick, by the fitted radii (pieces of a stem's surface; tree.cleanup."
        "inside_wood), then fit radii again (graph).",
        kind="enabled",
    )
    reversed_limbs: bool = _opt(
        True,
        "--reversed-limbs",
        "Turn round limbs the skeleton entered from a thin branch above and ran down to a "
        "thick base ending against the stem (tree.limbs.reversed_limbs), join stems and "
        "limbs broken by a gap in the scan to the wood just ahead that the skeleton reached "
        "the long way round (tree.limbs.broken_ends), then fit radii "
        "again. Default: on for both methods (the noisy synthetic maple's 67 mm limb; "
        "voxel since session 27: its truth table identical, the TreeLS plot 6,093 -> 5,919 L).",
        kind="enabled",
    )
    fork_hooks: bool = _opt(
        False,
        "--fork-hooks",
        "Straighten hooks at forks, where the skeleton entered one arm from a node up the "
        "other and came back down (tree.cleanup.fork_hooks; only where the way turns back "
        "at a node carrying other wood, outside the anchor's radius, and the points cover "
        "the straight way), then fit radii again. Opt-in: it takes the hook out of AdTree "
        "tree7's trunk (6.17 -> 5.84 m) but moves the synthetic classes within their "
        "seed noise, one cell in and one out (docs/tree.md, session 26).",
        kind="enabled",
    )
    detours: bool = _opt(
        True,
        "--detours",
        "Take the trunk's detours out along a branch and back out of the trunk where the "
        "stem's points cover the straight way (tree.cleanup.reroute_detours), then fit "
        "radii again.",
        kind="enabled",
    )


@dataclass(frozen=True)
class RadiusOptions:
    """Branch radii (:mod:`biomorph.tree.radius`)."""

    method: str = _opt("fit", "--radius", "fit (circle fits + taper model) or allometric.")
    recentre: bool = _opt(True, "--recentre", "Move nodes to fitted stem centres.", kind="enabled")
    search_factor: float = 1.5
    smooth: int = 2
    taper: bool = _opt(
        True,
        "--taper",
        "Keep circle fits only where the cross-section is "
        "well covered; elsewhere a taper model fitted on them "
        "(radius.taper_radii).",
        kind="enabled",
    )
    min_radius: float = _opt(
        0.001,
        "--min-radius",
        "Twig (tip) radius of the taper model, m: unmeasured tips end at it. Give the "
        "species' measured twig radius as rTwig does (e.g. 0.00423); default 1 mm.",
        lo=0,
    )
    twig_scale: bool = _opt(
        True,
        "--twig-scale",
        "Set the modelled twigs' radii to what their points say (radius.twig_offset); "
        "off when the species' twig radius is given as --min-radius.",
        kind="enabled",
    )
    run_cylinders: bool = _opt(
        True,
        "--run-cylinders",
        "Where no circle fit is reliable, measure the radius with a cylinder fitted to a "
        "run of nodes along the branch and put the nodes on its axis "
        "(radius.segment_radii; the synthetic presets' 2.5-7 cm class within 20 % of the "
        "truth on 15 of 16 runs, 11 without). Default: on for both methods (voxel since "
        "session 27: the birch preset's 2.5-7 cm class 113-184 %, 154-242 % without).",
        kind="enabled",
    )
    taper_exponent: float = _opt(
        2.0,
        "--taper-exponent",
        "Pipe-model exponent e of the taper model, r^e ∝ supported length "
        "(2: da Vinci's area-preserving branching).",
        lo=1,
        hi=4,
    )


@dataclass(frozen=True)
class OrderOptions:
    """Trunk and branch order (:mod:`biomorph.tree.order`); ``angle`` in radians.

    ``rule="supported"`` (default): each fork continues into the child carrying the most
    length; children carrying at least ``tie`` × that are codominant and the straightest
    of them continues (``tie`` 0.5: a fork whose lighter side carries at least half the
    heavier one's wood is codominant). ``rule="angle"``: the seed's rule with ``share``
    and ``angle`` as hard limits.
    """

    rule: str = _opt(
        "supported",
        "--order-rule",
        "supported (TreeQSM-style: the child "
        "carrying the most length continues, angle breaks ties) or angle "
        "(the seed's 45-degree rule).",
    )
    tie: float = _opt(
        0.5,
        "--order-tie",
        "Children carrying at least this share of the "
        "heaviest child's length are codominant (rule supported).",
        lo=0,
        hi=1,
        lo_open=True,
    )
    trunk_angle: float = _opt(
        math.radians(60.0),
        "--trunk-angle",
        "The trunk continues only into children within this angle of its axis "
        "(base to 1.3 m), degrees; 180 = follow the most wood (rule supported).",
        lo=0,
        hi=180,
        lo_open=True,
        kind="degrees",
    )
    trunk_smooth: bool = _opt(
        True,
        "--trunk-smooth",
        "Smooth the trunk's axis over a tenth of the tree's height once the trunk is "
        "chosen (order.smooth_trunk): the skeleton's node-to-node wiggle made a straight "
        "spruce's trunk 30 % longer than its height.",
        kind="enabled",
    )
    trunk_taper: bool = _opt(
        True,
        "--trunk-taper",
        "Make the trunk's radii non-increasing from the base up once the trunk is chosen "
        "(order.taper_trunk): circle fits at whorls take in branch bases and needles.",
        kind="enabled",
    )
    share: float = _opt(
        0.5, "--order-share", "Branch-order weight share (rule angle).", lo=0, hi=1, hi_open=True
    )
    angle: float = _opt(
        math.radians(45.0),
        "--order-angle",
        "Branch-order angle, degrees (rule angle).",
        lo=0,
        hi=180,
        lo_open=True,
        kind="degrees",
    )

    def rule_kwargs(self) -> dict[str, Any]:
        """Keyword arguments of :func:`biomorph.tree.order.continuation`."""
        return {
            "weight_share": self.share,
            "max_angle": self.angle,
            "rule": self.rule,
            "tie": self.tie,
            "trunk_angle": self.trunk_angle if self.trunk_angle < math.pi else None,
        }


STAGES = {
    "prepare": PrepareOptions,
    "graph": GraphOptions,
    "voxel": VoxelOptions,
    "cleanup": CleanupOptions,
    "radius": RadiusOptions,
    "order": OrderOptions,
}

#: the flat keyword arguments of the pre-options ``skeletonize`` → (stage, field)
_LEGACY = {
    "centre": ("prepare", "centre"),
    "filter": ("prepare", "filter"),
    "downsample": ("prepare", "downsample"),
    "outliers": ("prepare", "outliers"),
    "memory_check": ("prepare", "memory_check"),
    "units": ("prepare", "units"),
    "up": ("prepare", "up"),
    "ground": ("prepare", "ground"),
    "foliage": ("prepare", "foliage"),
    "foliage_passes": ("prepare", "foliage_passes"),
    "sparse_filter": ("prepare", "sparse_filter"),
    **{
        f: ("graph", f)
        for f in (
            "n_trees",
            "k",
            "search_radius",
            "node_spacing",
            "max_iter",
            "reweight",
            "root_slice",
            "min_tree_distance",
            "allometry_exponent",
            "edge_weights",
            "crown_partition",
        )
    },
    "cleanup": ("cleanup", "enabled"),
    **{
        f: ("cleanup", f)
        for f in (
            "radius_ratio",
            "length_factor",
            "overlap",
            "min_branch_length",
            "min_cylinder_radius",
            "tip_support",
            "residual",
            "residual_threshold",
            "empty_tips",
            "inside_wood",
            "reversed_limbs",
            "fork_hooks",
            "detours",
        )
    },
    "radius": ("radius", "method"),
    "recentre": ("radius", "recentre"),
    "search_factor": ("radius", "search_factor"),
    "smooth": ("radius", "smooth"),
    "min_radius": ("radius", "min_radius"),
    "twig_scale": ("radius", "twig_scale"),
    "run_cylinders": ("radius", "run_cylinders"),
    "order_share": ("order", "share"),
    "order_angle": ("order", "angle"),
    "order_rule": ("order", "rule"),
    "order_tie": ("order", "tie"),
    "trunk_smooth": ("order", "trunk_smooth"),
    "trunk_taper": ("order", "trunk_taper"),
}


@dataclass(frozen=True)
class SkeletonizeOptions:
    """Everything :func:`biomorph.tree.skeletonize` reads: method, seed and one options
    object per stage. Frozen: derive variants with :meth:`replace`."""

    method: str = "graph"
    seed: int = 0
    prepare: PrepareOptions = field(default_factory=PrepareOptions)
    graph: GraphOptions = field(default_factory=GraphOptions)
    voxel: VoxelOptions = field(default_factory=VoxelOptions)
    cleanup: CleanupOptions = field(default_factory=CleanupOptions)
    radius: RadiusOptions = field(default_factory=RadiusOptions)
    order: OrderOptions = field(default_factory=OrderOptions)

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> None:
        """Raise :class:`ParameterError` on a value no stage accepts."""
        if self.method not in METHODS:
            raise ParameterError(
                f"unknown method {self.method!r}; expected one of {', '.join(METHODS)}"
            )
        if self.radius.method not in ("fit", "allometric"):
            raise ParameterError(
                f"radius must be 'fit' or 'allometric', got {self.radius.method!r}"
            )
        if self.order.rule not in ("supported", "angle"):
            raise ParameterError(f"order rule {self.order.rule!r}; expected 'supported' or 'angle'")
        if self.prepare.units is not None and self.prepare.units not in UNITS:
            raise ParameterError(
                f"units {self.prepare.units!r}; expected one of {', '.join(UNITS)}"
            )
        if self.prepare.up is not None and self.prepare.up not in UP_AXES:
            raise ParameterError(
                f"up axis {self.prepare.up!r}; expected one of {', '.join(UP_AXES)}"
            )
        fol = self.prepare.foliage
        if isinstance(fol, str) and fol != "auto":
            raise ParameterError(f"foliage {fol!r}; expected 'auto', None or a factor > 1")
        for name, value, cls in (
            ("prepare", self.prepare, PrepareOptions),
            ("graph", self.graph, GraphOptions),
            ("voxel", self.voxel, VoxelOptions),
            ("cleanup", self.cleanup, CleanupOptions),
            ("radius", self.radius, RadiusOptions),
            ("order", self.order, OrderOptions),
        ):
            if not isinstance(value, cls):
                raise ParameterError(
                    f"options.{name} must be a {cls.__name__}, got {type(value).__name__}"
                )

    def replace(self, **changes: Any) -> SkeletonizeOptions:
        """A copy with top-level fields (``method``, ``seed``, a stage) replaced."""
        return dataclasses.replace(self, **changes)

    @classmethod
    def from_kwargs(
        cls,
        method: str = "graph",
        seed: int = 0,
        base: SkeletonizeOptions | None = None,
        **kwargs: Any,
    ) -> SkeletonizeOptions:
        """Options from the flat keywords of the pre-options ``skeletonize`` (``k=12``,
        ``order_angle=…``, ``voxel={"cell_size": 0.05}``, ``filter={...}``, …)."""
        base = base or cls()
        stages: dict[str, dict[str, Any]] = {s: {} for s in STAGES}
        for key, value in kwargs.items():
            if key == "voxel":
                stages["voxel"].update(dict(value or {}))
                continue
            if key not in _LEGACY:
                raise ParameterError(
                    f"skeletonize got an unknown option {key!r}; expected "
                    f"one of {', '.join(sorted([*_LEGACY, 'voxel']))}"
                )
            stage, name = _LEGACY[key]
            stages[stage][name] = _legacy_value(key, value)
        changes: dict[str, Any] = {}
        for stage, vals in stages.items():
            if vals:
                try:
                    changes[stage] = dataclasses.replace(getattr(base, stage), **vals)
                except TypeError as exc:
                    raise ParameterError(f"{stage} options: {exc}") from None
        return dataclasses.replace(base, method=method, seed=seed, **changes)

    @classmethod
    def from_cli(
        cls, values: dict[str, Any], method: str = "graph", seed: int = 0
    ) -> SkeletonizeOptions:
        """Options from the values of the generated CLI options (keys as in
        :func:`cli_fields`: ``"<stage>.<field>"``), converting degrees, ``--no-ground``,
        ``--foliage 0`` and ``--filter NAME:MAX``."""
        stages: dict[str, dict[str, Any]] = {s: {} for s in STAGES}
        for stage, f, spec in cli_fields():
            key = f"{stage}.{f.name}"
            if key in values:
                stages[stage][f.name] = _from_cli(spec, values[key])
        base = cls()
        return dataclasses.replace(
            base,
            method=method,
            seed=seed,
            **{s: dataclasses.replace(getattr(base, s), **v) for s, v in stages.items() if v},
        )

    def to_dict(self) -> dict[str, Any]:
        """Nested plain dict (JSON-ready; angles in radians)."""
        return dataclasses.asdict(self)


def _legacy_value(key: str, value: Any) -> Any:
    if key == "filter" and value is not None and not isinstance(value, AttributeFilter):
        if isinstance(value, dict):
            return AttributeFilter(**value)
        return AttributeFilter(*value)
    if key == "downsample" and isinstance(value, dict):
        raise ParameterError(
            "downsample: give a ratio (PrepareOptions.downsample) and/or "
            "PrepareOptions.downsample_voxel, not a dict"
        )
    if key == "outliers" and isinstance(value, dict):
        raise ParameterError(
            "outliers: give PrepareOptions(outlier_k=..., outlier_std=...), not a dict"
        )
    return value


def _from_cli(spec: CliField, value: Any) -> Any:
    if spec.kind == "degrees":
        return math.radians(value)
    if spec.kind == "ground":
        return "auto" if value else None
    if spec.kind == "foliage":
        if value is None:
            return "auto"
        if value != 0 and not value > 1:
            raise ParameterError(f"--foliage must be 0 (off) or a factor > 1, got {value}")
        return value or None
    if spec.kind == "filter":
        return None if value is None else AttributeFilter.parse(value)
    return value


_CLI_TYPES: dict[str, Any] = {
    "int": int,
    "int | None": int | None,
    "float": float,
    "float | None": float | None,
    "str": str,
    "bool": bool,
    "str | None": str | None,
    "bool | None": bool | None,
}
_KIND_TYPES: dict[str, Any] = {
    "degrees": float,
    "ground": bool,
    "enabled": bool,
    "foliage": float | None,
    "filter": str | None,
}


def cli_type(f: dataclasses.Field, spec: CliField) -> Any:
    """The Python type of the option on the command line."""
    if spec.kind is not None:
        return _KIND_TYPES[spec.kind]
    return _CLI_TYPES[str(f.type)]


def cli_default(f: dataclasses.Field, spec: CliField) -> Any:
    """The option's default on the command line (degrees, flags, ...)."""
    if spec.kind == "degrees":
        return round(math.degrees(f.default), 9)
    if spec.kind == "ground":
        return f.default is not None
    if spec.kind in ("foliage", "filter"):
        return None
    return f.default


def cli_fields() -> list[tuple[str, dataclasses.Field, CliField]]:
    """``(stage, field, CliField)`` of every option shown on the command line."""
    out = []
    for stage, cls in STAGES.items():
        for f in dataclasses.fields(cls):
            spec = f.metadata.get("cli")
            if spec is not None:
                out.append((stage, f, spec))
    return out
