"""JointSkeleton: a joint hierarchy (creature and motion pillars).

Structure of arrays, parents before children (``parent[i] < i``, ``parent[0] == -1``), so a
single forward pass over depth levels gives world transforms for any number of frames.

Frames: Y-up, metres (BVH/glTF convention). Joint ``i``'s local transform is
``T(offset[i]) @ R(rest_rotation[i]) @ R(pose_rotation[i])``; the root may be translated by
a per-frame root position which replaces its offset.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike, NDArray

from biomorph.core import transforms as tf
from biomorph.errors import InputError


@dataclass(frozen=True, eq=False)
class JointSkeleton:
    """A joint hierarchy.

    Attributes
    ----------
    names : joint names, unique.
    parent : ``int[n]``, -1 for roots, ``parent[i] < i``.
    offset : ``float[n, 3]`` rest translation of each joint in its parent's frame (metres).
    rest_rotation : ``float[n, 4]`` rest orientation relative to the parent (quaternion xyzw).
    limits : ``float[n, 3, 2]`` (min, max) rotation limits (rad) about local x, y, z.
    channels : per joint, BVH channel names in file order (e.g.
        ``("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation")``),
        kept so a BVH round-trips; ``None`` if the skeleton did not come from BVH.
    end_site : ``float[n, 3]`` offset of a BVH ``End Site`` below the joint, NaN where none.
    """

    names: tuple[str, ...]
    parent: NDArray[np.int64]
    offset: NDArray[np.float64]
    rest_rotation: NDArray[np.float64] = field(default=None)  # type: ignore[arg-type]
    limits: NDArray[np.float64] = field(default=None)  # type: ignore[arg-type]
    channels: tuple[tuple[str, ...], ...] | None = None
    end_site: NDArray[np.float64] = field(default=None)  # type: ignore[arg-type]

    def __post_init__(self) -> None:
        n = len(self.names)
        object.__setattr__(self, "names", tuple(str(s) for s in self.names))
        parent = np.asarray(self.parent, dtype=np.int64).reshape(-1)
        offset = np.asarray(self.offset, dtype=float).reshape(-1, 3)
        if parent.shape != (n,) or offset.shape != (n, 3):
            raise InputError(
                f"skeleton with {n} names needs parent[{n}] and offset[{n},3]; "
                f"got {parent.shape} and {offset.shape}"
            )
        if n == 0:
            raise InputError("skeleton has no joints; expected at least one")
        if parent[0] != -1 or np.any(parent[1:] >= np.arange(1, n)) or np.any(parent < -1):
            raise InputError("skeleton parents must precede children (parent[i] < i, root -1)")
        if len(set(self.names)) != n:
            dup = [s for s in self.names if self.names.count(s) > 1][0]
            raise InputError(f"joint name {dup!r} occurs more than once; names must be unique")
        rest = (
            tf.quat_identity((n,))
            if self.rest_rotation is None
            else np.asarray(self.rest_rotation, dtype=float).reshape(n, 4)
        )
        limits = self.limits
        if limits is None:
            limits = np.tile(np.array([-np.pi, np.pi]), (n, 3, 1))
        limits = np.asarray(limits, dtype=float).reshape(n, 3, 2)
        end = (
            np.full((n, 3), np.nan)
            if self.end_site is None
            else np.asarray(self.end_site, dtype=float).reshape(n, 3)
        )
        if self.channels is not None and len(self.channels) != n:
            raise InputError(f"channels given for {len(self.channels)} joints, expected {n}")
        for name, arr in (
            ("parent", parent),
            ("offset", offset),
            ("rest_rotation", rest),
            ("limits", limits),
            ("end_site", end),
        ):
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        if self.channels is not None:
            object.__setattr__(self, "channels", tuple(tuple(c) for c in self.channels))

    # ------------------------------------------------------------------ structure
    @property
    def n_joints(self) -> int:
        return len(self.names)

    def __len__(self) -> int:
        return len(self.names)

    def index(self, name: str) -> int:
        """Index of joint ``name``; :class:`InputError` listing a few names if absent."""
        try:
            return self._name_index[name]
        except KeyError:
            raise InputError(
                f"no joint named {name!r}; joints are "
                f"{', '.join(self.names[:8])}{' …' if len(self) > 8 else ''}"
            ) from None

    @cached_property
    def _name_index(self) -> dict[str, int]:
        return {s: i for i, s in enumerate(self.names)}

    @cached_property
    def depth(self) -> NDArray[np.int64]:
        """Number of ancestors of each joint (root 0)."""
        # parents precede children, so index order is a topological order
        from biomorph.core import treeops  # numba + scipy.sparse: loaded on first use

        return treeops.depth(self.parent, np.arange(len(self), dtype=np.int64))

    @cached_property
    def levels(self) -> list[NDArray[np.int64]]:
        """Joint indices grouped by depth, root level first (for vectorised passes)."""
        order = np.argsort(self.depth, kind="stable")
        counts = np.bincount(self.depth)
        return np.split(order, np.cumsum(counts)[:-1])

    def children(self, joint: int | str) -> NDArray[np.int64]:
        """Indices of the direct children of ``joint``."""
        j = self.index(joint) if isinstance(joint, str) else int(joint)
        return np.flatnonzero(self.parent == j)

    def descendants(self, joint: int | str, include_self: bool = True) -> NDArray[np.int64]:
        """Indices of the subtree below ``joint`` ("hierarchy below"), in index order."""
        j = self.index(joint) if isinstance(joint, str) else int(joint)
        mark = np.zeros(len(self))
        mark[j] = 1.0
        from biomorph.core import treeops  # numba + scipy.sparse: loaded on first use

        mask = treeops.accumulate_down(self.parent, mark, np.arange(len(self), dtype=np.int64)) > 0
        if not include_self:
            mask[j] = False
        return np.flatnonzero(mask)

    def with_(self, **changes: object) -> JointSkeleton:
        """A copy with some fields replaced (the skeleton itself is immutable)."""
        return replace(self, **changes)  # type: ignore[arg-type]

    # ------------------------------------------------------------------ kinematics
    def local_matrices(
        self, rotation: ArrayLike | None = None, root_position: ArrayLike | None = None
    ) -> NDArray[np.float64]:
        """Local 4x4 transforms ``(..., n, 4, 4)``.

        ``rotation`` ``(..., n, 4)`` are pose quaternions applied after the rest rotation;
        ``root_position`` ``(..., 3)`` replaces the root joint's offset (per frame).
        """
        n = len(self)
        rest = self.rest_rotation
        if rotation is None:
            q = np.broadcast_to(rest, (n, 4))
        else:
            rot = np.asarray(rotation, dtype=float)
            if rot.shape[-2:] != (n, 4):
                raise InputError(f"rotation has shape {rot.shape}; expected (..., {n}, 4)")
            q = tf.quat_multiply(rest, rot)
        lead = q.shape[:-2]
        t = np.broadcast_to(self.offset, lead + (n, 3)).copy()
        if root_position is not None:
            rp = np.asarray(root_position, dtype=float)
            lead = np.broadcast_shapes(lead, rp.shape[:-1])
            t = np.broadcast_to(t, lead + (n, 3)).copy()
            q = np.broadcast_to(q, lead + (n, 4))
            roots = self.parent < 0
            t[..., roots, :] = rp[..., None, :]
        # explicit matrices: (n, 4) quaternions with n == 4 look like one 4x4 matrix
        return tf.make_transform(tf.quat_to_matrix(q), t)

    def world_matrices(self, local: ArrayLike | None = None) -> NDArray[np.float64]:
        """World transforms ``(..., n, 4, 4)`` from local ones (default: rest pose).

        One batched matrix product per hierarchy level, so cost is O(depth) NumPy calls.
        """
        loc = self.local_matrices() if local is None else np.asarray(local, dtype=float)
        world = np.array(loc, copy=True)
        for level in self.levels[1:]:
            world[..., level, :, :] = world[..., self.parent[level], :, :] @ loc[..., level, :, :]
        return world

    def world_positions(
        self, rotation: ArrayLike | None = None, root_position: ArrayLike | None = None
    ) -> NDArray[np.float64]:
        """Joint positions in world space ``(..., n, 3)`` for a pose (default: rest pose)."""
        return self.world_matrices(self.local_matrices(rotation, root_position))[..., :3, 3]

    def bone_segments(self, world: ArrayLike | None = None) -> NDArray[np.float64]:
        """Line segments ``(m, 2, 3)`` parent->child joint for drawing (rest pose default)."""
        w = self.world_matrices() if world is None else np.asarray(world, dtype=float)
        child = np.flatnonzero(self.parent >= 0)
        p = w[..., :3, 3]
        return np.stack([p[..., self.parent[child], :], p[..., child, :]], axis=-2)


def ancestors(parent: ArrayLike, joint: int) -> list[int]:
    """``joint`` and its ancestors up to the root, nearest first."""
    par = np.asarray(parent)
    out = [int(joint)]
    while par[out[-1]] >= 0:
        out.append(int(par[out[-1]]))
    return out


def common_ancestor(parent: ArrayLike, joints: Sequence[int]) -> int:
    """The nearest joint, not one of ``joints``, above every joint of ``joints`` (for feet:
    the pelvis the legs hang from); the root (0) when there is none."""
    chain = ancestors(parent, joints[0])
    common = set(chain)
    for j in joints[1:]:
        common &= set(ancestors(parent, j))
    return next((j for j in chain if j in common and j not in joints), 0)
