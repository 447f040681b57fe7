"""PointCloud: float64 xyz plus named per-point attributes (tree pillar, I/O)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from biomorph.errors import InputError


@dataclass(frozen=True, eq=False)
class PointCloud:
    """A point cloud.

    Attributes
    ----------
    xyz : ``float64[n, 3]`` coordinates in metres (Z up), relative to ``offset``.
    attributes : per-point arrays of length ``n`` by name (``intensity``, ``Deviation``,
        ``classification``, ``red`` …), kept through I/O.
    offset : ``float64[3]`` added to ``xyz`` to get the original (e.g. georeferenced)
        coordinates; set by centring so outputs can be written back in the source frame.
    meta : format details kept for round-trips (LAS scales/offsets, point format, CRS …).
    source : path the cloud was read from, if any (for error messages).
    """

    xyz: NDArray[np.float64]
    attributes: dict[str, NDArray] = field(default_factory=dict)
    offset: NDArray[np.float64] = field(default_factory=lambda: np.zeros(3))
    meta: dict[str, object] = field(default_factory=dict)
    source: str | None = None

    def __post_init__(self) -> None:
        xyz = np.asarray(self.xyz, dtype=np.float64)
        if xyz.ndim != 2 or xyz.shape[1] != 3:
            raise InputError(
                f"{self.source or 'point cloud'}: coordinates have shape "
                f"{xyz.shape}; expected (n, 3)"
            )
        object.__setattr__(self, "xyz", xyz)
        object.__setattr__(self, "offset", np.asarray(self.offset, dtype=np.float64).reshape(3))
        attrs = {}
        for k, v in self.attributes.items():
            a = np.asarray(v)
            if a.shape[0] != xyz.shape[0]:
                raise InputError(
                    f"attribute {k!r} has {a.shape[0]} values for {xyz.shape[0]} points"
                )
            attrs[k] = a
        object.__setattr__(self, "attributes", attrs)

    @property
    def n_points(self) -> int:
        return int(self.xyz.shape[0])

    def __len__(self) -> int:
        return self.n_points

    @property
    def world_xyz(self) -> NDArray[np.float64]:
        """Coordinates in the original frame (``xyz + offset``)."""
        return self.xyz + self.offset

    def bounds(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """(min, max) corners of the bounding box in the cloud's frame."""
        if self.n_points == 0:
            raise InputError(f"{self.source or 'point cloud'} is empty; expected points")
        return self.xyz.min(axis=0), self.xyz.max(axis=0)

    def select(self, mask_or_index: ArrayLike) -> PointCloud:
        """Subset of points (boolean mask or index array), attributes kept."""
        sel = np.asarray(mask_or_index)
        return replace(
            self, xyz=self.xyz[sel], attributes={k: v[sel] for k, v in self.attributes.items()}
        )

    def with_(self, **changes: object) -> PointCloud:
        return replace(self, **changes)  # type: ignore[arg-type]
