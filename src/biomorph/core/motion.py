"""The :class:`Motion` type: a joint skeleton animated over frames (core layer).

Lives in ``core/`` beside :class:`~biomorph.core.skeleton.JointSkeleton` so the readers in
``io/`` (BVH, ASF/AMC, HTR) and shared services (``render``) build motions without importing
the motion pillar (issue 12); ``biomorph.motion`` re-exports every name here. The two
compiled kernels the type needs (forward kinematics and slerp sampling) live in
:mod:`biomorph.core._motion_kernels`, loaded only for large work (:func:`use_compiled`): a
small file is read, described and converted without importing numba; the operators'
kernels stay in ``biomorph.motion._kernels``.

Data layout (structure of arrays, one row per frame):

* ``skeleton`` – :class:`biomorph.core.skeleton.JointSkeleton` (names, parents, rest offsets,
  rest rotations, BVH channel names per joint, End Sites).
* ``rotation`` – ``float[f, n, 4]`` unit quaternions, scalar-last ``(x, y, z, w)``: the pose
  rotation of every joint *applied after its rest rotation* (local transform of joint ``j`` is
  ``T(offset_j) · R(rest_j) · R(rotation[:, j])``). Hemisphere-continuous over time: consecutive
  quaternions of one joint have a non-negative dot product, so every component is a
  continuous signal that can be filtered or interpolated.
* ``root_position`` – ``float[f, 3]`` translation of the root joint in its parent (world)
  frame; it *replaces* the root's rest offset (BVH convention).
* ``frame_time`` – seconds between frames (``fps = 1 / frame_time``).
* ``joint_translation`` – optional ``float[f, n, 3]`` local translation of every joint per frame
  (NaN-free: joints without position channels hold their rest offset, the root column equals
  ``root_position``). Present only when some non-root joint is translated (BVH position
  channels on inner joints, HTR per-segment translations); ``None`` otherwise.
* ``meta`` – free-form information from the reader (source path, units, up axis, number of
  ±180° Euler wraps in the file, …). Never used by the maths.

Units: lengths in the file's units for BVH (BVH has no unit field), metres for HTR and
ASF/AMC (converted from the declared units); angles in radians; time in seconds. Motion
data are Y-up by convention; :func:`guess_up_axis` detects Z-up files and
:func:`to_y_up` converts them.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any, overload

import numpy as np
from numpy.typing import ArrayLike, NDArray

from biomorph.core import transforms as tf
from biomorph.core.skeleton import JointSkeleton
from biomorph.core.types import Array
from biomorph.errors import InputError, ParameterError

ROTATION_CHANNELS = ("Xrotation", "Yrotation", "Zrotation")
POSITION_CHANNELS = ("Xposition", "Yposition", "Zposition")
DEFAULT_ORDER = "ZXY"


class MotionInputWarning(UserWarning):
    """A reader tolerated an irregular file (e.g. ``Frames:`` disagreeing with the data rows);
    the same message is kept in ``motion.meta["tolerated"]``."""


def tolerate(meta: dict[str, Any], message: str) -> None:
    """Record in ``meta["tolerated"]`` and warn (one line) that a reader accepted ``message``."""
    import warnings

    meta.setdefault("tolerated", []).append(message)
    warnings.warn(message, MotionInputWarning, stacklevel=3)


@overload
def frozen(a: Array) -> Array: ...
@overload
def frozen(a: None) -> None: ...
@overload
def frozen(a: Array | None) -> Array | None: ...


def frozen(a: Array | None) -> Array | None:
    """Mark a freshly computed array read-only so :class:`Motion` takes it without copying
    (internal: only for arrays nobody else holds)."""
    if a is not None:
        a.setflags(write=False)
    return a


def _readonly(a: ArrayLike, shape_tail: tuple[int, ...], name: str) -> Array:
    arr = np.asarray(a, dtype=np.float64)
    if arr.ndim != 1 + len(shape_tail) or arr.shape[1:] != shape_tail:
        raise InputError(
            f"Motion.{name} has shape {arr.shape}; expected (frames, "
            f"{', '.join(map(str, shape_tail))})"
        )
    if arr.flags.writeable:
        arr = np.array(arr, dtype=np.float64, order="C", copy=True)
        arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class Motion:
    """A skeleton animated over ``n_frames`` frames (see the module docstring for layout).

    Example
    -------
    >>> import biomorph as bm                                   # doctest: +SKIP
    >>> mo = bm.io.read_bvh("walk.bvh")                         # doctest: +SKIP
    >>> mo.n_frames, mo.fps, mo.world_positions().shape         # doctest: +SKIP
    (327, 120.0, (327, 31, 3))
    """

    skeleton: JointSkeleton
    rotation: Array
    root_position: Array
    frame_time: float
    joint_translation: Array | None = None
    meta: dict[str, Any] = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        n = self.skeleton.n_joints
        rot = _readonly(self.rotation, (n, 4), "rotation")
        pos = _readonly(self.root_position, (3,), "root_position")
        if pos.shape[0] != rot.shape[0]:
            raise InputError(
                f"Motion has {rot.shape[0]} rotation frames but {pos.shape[0]} "
                "root positions; expected the same number"
            )
        ft = float(self.frame_time)
        if not np.isfinite(ft) or ft <= 0:
            raise InputError(
                f"frame time {self.frame_time!r} s is not positive; expected seconds per frame > 0"
            )
        object.__setattr__(self, "rotation", rot)
        object.__setattr__(self, "root_position", pos)
        object.__setattr__(self, "frame_time", ft)
        if self.joint_translation is not None:
            jt = _readonly(self.joint_translation, (n, 3), "joint_translation")
            if jt.shape[0] != rot.shape[0]:
                raise InputError(
                    f"joint_translation has {jt.shape[0]} frames; expected {rot.shape[0]}"
                )
            object.__setattr__(self, "joint_translation", jt)
        object.__setattr__(self, "meta", dict(self.meta))

    # ------------------------------------------------------------------ basic properties
    @property
    def n_frames(self) -> int:
        return int(self.rotation.shape[0])

    @property
    def n_joints(self) -> int:
        return self.skeleton.n_joints

    @property
    def names(self) -> tuple[str, ...]:
        return self.skeleton.names

    @property
    def fps(self) -> float:
        """Frames per second (``1 / frame_time``)."""
        return 1.0 / self.frame_time

    @property
    def duration(self) -> float:
        """Seconds from the first to the last frame, ``(n_frames - 1) * frame_time``."""
        return max(self.n_frames - 1, 0) * self.frame_time

    def __len__(self) -> int:
        return self.n_frames

    def __repr__(self) -> str:
        return (
            f"Motion({self.n_frames} frames @ {self.fps:.6g} fps, {self.n_joints} joints, "
            f"root {self.skeleton.names[0]!r})"
        )

    def with_(self, **changes: Any) -> Motion:
        """A copy with some fields replaced (the motion itself is immutable)."""
        return replace(self, **changes)

    @property
    def rotation_orders(self) -> tuple[str, ...]:
        """Per joint, the axes of its rotation channels in file order (``"ZXY"`` default).

        A joint with fewer than three rotation channels gets its listed axes followed by
        the missing ones (which are then always zero in the file)."""
        chans = self.skeleton.channels
        out = []
        for j in range(self.n_joints):
            axes = ""
            if chans is not None:
                axes = "".join(c[0].upper() for c in chans[j] if c.lower().endswith("rotation"))
            if len(axes) < 3:
                axes = (
                    axes + "".join(a for a in DEFAULT_ORDER if a not in axes)
                    if axes
                    else DEFAULT_ORDER
                )
            out.append(axes)
        return tuple(out)

    # ------------------------------------------------------------------ frames
    def __getitem__(self, index: int | slice | ArrayLike) -> Motion:
        """Frames ``index`` (slice, int or integer array) as a new Motion."""
        if isinstance(index, (int, np.integer)):
            index = slice(int(index), int(index) + 1 if int(index) != -1 else None)
        if not isinstance(index, slice):
            index = np.asarray(index, dtype=np.int64)
        rot = self.rotation[index]
        if rot.shape[0] == 0:
            raise InputError(
                f"frame selection {index!r} is empty; the motion has {self.n_frames} frames"
            )
        jt = None if self.joint_translation is None else self.joint_translation[index]
        return Motion(self.skeleton, rot, self.root_position[index], self.frame_time, jt, self.meta)

    def frames(self, start: int, stop: int) -> Motion:
        """Frames ``start <= i < stop`` with a clear error if the range is empty or outside."""
        check_range(self, start, stop)
        return self[start:stop]

    def sample(self, t: ArrayLike) -> Motion:
        """Motion at fractional frame indices ``t`` (clamped to the clip).

        Rotations by slerp, translations linearly. Integer ``t`` returns the stored frames
        exactly (no rounding from interpolation)."""
        t = np.clip(np.asarray(t, dtype=float).reshape(-1), 0.0, self.n_frames - 1)
        rot, pos, jt = sample_arrays(self, t)
        return Motion(self.skeleton, rot, pos, self.frame_time, jt, self.meta)

    def resample(self, fps: float) -> Motion:
        """The motion at another frame rate (slerp for rotations, linear for translations).

        The duration is kept; the new frame count is ``floor(duration * fps + 1e-9) + 1``."""
        fps = float(fps)
        if not np.isfinite(fps) or fps <= 0:
            raise ParameterError(f"fps {fps} is not positive; expected frames per second > 0")
        n_new = int(np.floor(self.duration * fps + 1e-9)) + 1
        t = np.arange(n_new) * (self.fps / fps)
        out = self.sample(t)
        return out.with_(frame_time=1.0 / fps)

    def concatenate(self, *others: Motion) -> Motion:
        """This motion followed by ``others`` (same joint names); frame time of the first."""
        return concatenate([self, *others])

    # ------------------------------------------------------------------ kinematics
    def local_translations(self, frames: ArrayLike | slice | None = None) -> Array:
        """Local translation of every joint ``float[f, n, 3]`` (root = root position)."""
        sel: Any = slice(None) if frames is None else frames
        if self.joint_translation is not None:
            return np.array(self.joint_translation[sel])
        pos = self.root_position[sel]
        t = np.broadcast_to(self.skeleton.offset, pos.shape[:-1] + self.skeleton.offset.shape)
        t = np.array(t)
        t[..., 0, :] = pos
        return t

    def world_matrices(self, frames: ArrayLike | slice | None = None) -> Array:
        """World 4x4 transforms of every joint ``float[f, n, 4, 4]`` (vectorised FK)."""
        sel: Any = slice(None) if frames is None else frames
        q = tf.quat_multiply(self.skeleton.rest_rotation, self.rotation[sel])
        return self.skeleton.world_matrices(_transforms(q, self.local_translations(sel)))

    def _fk(self, frames: ArrayLike | slice | None) -> tuple[Array, Array]:
        sel: Any = slice(None) if frames is None else frames
        rot = np.ascontiguousarray(self.rotation[sel])
        lead = rot.shape[:-2]
        rot = rot.reshape(-1, self.n_joints, 4)
        trans = np.ascontiguousarray(self.local_translations(sel)).reshape(-1, self.n_joints, 3)
        pos = np.empty(trans.shape)
        quat = np.empty(rot.shape)
        if use_compiled(rot.shape[0] * rot.shape[1]):
            from biomorph.core._motion_kernels import fk_positions

            fk_positions(
                ro(self.skeleton.rest_rotation),
                ro(rot),
                ro(trans),
                ro_int(self.skeleton.parent),
                pos,
                quat,
            )
        else:
            fk_numpy(self.skeleton.rest_rotation, rot, trans, self.skeleton.parent, pos, quat)
        return pos.reshape(lead + pos.shape[1:]), quat.reshape(lead + quat.shape[1:])

    def world_positions(self, frames: ArrayLike | slice | None = None) -> Array:
        """World position of every joint ``float[f, n, 3]`` (file units / metres); one
        compiled pass over frames and joints (parents first)."""
        return self._fk(frames)[0]

    def world_rotations(self, frames: ArrayLike | slice | None = None) -> Array:
        """World orientation quaternions ``float[f, n, 4]`` of every joint."""
        return self._fk(frames)[1]

    # ------------------------------------------------------------------ Euler views
    def euler(
        self,
        joint: int | str,
        degrees: bool = False,
        order: str | None = None,
        include_rest: bool = False,
    ) -> Array:
        """Euler angles ``float[f, 3]`` of ``joint`` in its channel order (or ``order``),
        unwrapped over time (no ±360° jumps). ``include_rest`` composes the rest rotation
        (what a BVH file stores when the skeleton has non-identity rest rotations)."""
        j = self.skeleton.index(joint) if isinstance(joint, str) else int(joint)
        o = order or self.rotation_orders[j]
        q = self.rotation[:, j]
        if include_rest:
            q = tf.quat_multiply(self.skeleton.rest_rotation[j], q)
        e = tf.quat_to_euler(q, o, degrees=degrees)
        return tf.unwrap_euler(e, degrees=degrees, axis=0)

    def channel(self, joint: int | str, name: str, degrees: bool = False) -> Array:
        """One scalar channel ``float[f]`` of a joint: ``"Xrotation"``.. (Euler, unwrapped,
        in the joint's channel order) or ``"Xposition"``.. (local translation)."""
        j = self.skeleton.index(joint) if isinstance(joint, str) else int(joint)
        key = _channel_key(name)
        axis = "XYZ".index(key[0])
        if key.endswith("position"):
            return self.local_translations()[:, j, axis]
        order = self.rotation_orders[j]
        return self.euler(j, degrees=degrees)[:, order.index(key[0])]


def _transforms(q: Array, t: Array) -> Array:
    """4x4 transforms from quaternions ``(..., 4)`` and translations ``(..., 3)`` (no
    shape guessing, unlike ``make_transform`` which cannot tell 4 joints from a 4x4)."""
    out = np.zeros(q.shape[:-1] + (4, 4))
    out[..., :3, :3] = tf.quat_to_matrix(q)
    out[..., :3, 3] = t
    out[..., 3, 3] = 1.0
    return out


def _channel_key(name: str) -> str:
    s = name.strip().lower()
    table = {
        "rx": "Xrotation",
        "ry": "Yrotation",
        "rz": "Zrotation",
        "tx": "Xposition",
        "ty": "Yposition",
        "tz": "Zposition",
    }
    if s in table:
        return table[s]
    for c in ROTATION_CHANNELS + POSITION_CHANNELS:
        if s == c.lower():
            return c
    raise ParameterError(
        f"channel {name!r} is not one of Xrotation Yrotation Zrotation "
        "Xposition Yposition Zposition (or rx ry rz tx ty tz)"
    )


def check_range(motion: Motion, start: int, stop: int, what: str = "frame range") -> None:
    """Raise :class:`ParameterError` unless ``0 <= start < stop <= n_frames``."""
    if not (0 <= start < stop <= motion.n_frames):
        raise ParameterError(
            f"{what} {start}:{stop} is empty or outside the clip; expected "
            f"0 <= start < stop <= {motion.n_frames}"
        )


def sample_arrays(motion: Motion, t: Array) -> tuple[Array, Array, Array | None]:
    """Rotations (slerp), root positions and joint translations (linear) at frames ``t``."""
    i0, frac, pos, jt = sample_linear(motion, t)
    rot = np.empty((t.size,) + motion.rotation.shape[1:])
    if use_compiled(rot.shape[0] * rot.shape[1]):
        from biomorph.core._motion_kernels import sample_slerp

        sample_slerp(ro(motion.rotation), ro_int(i0), ro(frac), rot)
    else:
        slerp_numpy(motion.rotation, i0, frac, rot)
    return frozen(rot), pos, jt


def sample_linear(motion: Motion, t: Array) -> tuple[NDArray[np.int64], Array, Array, Array | None]:
    """The sampling of :func:`sample_arrays` without the rotations: ``(i0, frac, root
    positions, joint translations)`` at frames ``t`` (rotations: slerp ``i0 → i0 + 1`` by
    ``frac``, done by the caller's kernel)."""
    n = motion.n_frames
    i0 = np.floor(t).astype(np.int64)
    i0 = np.clip(i0, 0, n - 1)
    i1 = np.minimum(i0 + 1, n - 1)
    frac = t - i0
    exact = frac == 0.0
    f = frac[:, None]
    pos = motion.root_position[i0] * (1.0 - f) + motion.root_position[i1] * f
    pos[exact] = motion.root_position[i0[exact]]
    jt = None
    if motion.joint_translation is not None:
        a = motion.joint_translation[i0]
        b = motion.joint_translation[i1]
        jt = a * (1.0 - f[:, :, None]) + b * f[:, :, None]
        jt[exact] = a[exact]
    return i0, frac, frozen(pos), frozen(jt)


def same_skeleton(a: JointSkeleton, b: JointSkeleton, what: str = "motions") -> None:
    """Raise :class:`InputError` unless both skeletons have the same joint names in order."""
    if a.names != b.names:
        extra = sorted(set(a.names) ^ set(b.names))
        detail = (
            f"joints only in one of them: {', '.join(extra[:6])}"
            if extra
            else "same joints in a different order"
        )
        raise InputError(
            f"{what} do not share a skeleton ({a.n_joints} vs {b.n_joints} "
            f"joints; {detail}); expected identical joint names"
        )


def concatenate(motions: Sequence[Motion]) -> Motion:
    """Frames of several motions one after another (same joint names, hemisphere-continuous
    at the joins). The first motion's skeleton and frame time are used."""
    if not motions:
        raise InputError("nothing to concatenate; expected at least one motion")
    first = motions[0]
    for m in motions[1:]:
        same_skeleton(first.skeleton, m.skeleton)
    rot = tf.quat_continuous(np.concatenate([m.rotation for m in motions]), axis=0)
    pos = np.concatenate([m.root_position for m in motions])
    jt = None
    if any(m.joint_translation is not None for m in motions):
        jt = np.concatenate([m.local_translations() for m in motions])
    return Motion(first.skeleton, rot, pos, first.frame_time, jt, first.meta)


def dfs_preorder(parent: ArrayLike) -> NDArray[np.int64]:
    """Depth-first pre-order of a joint hierarchy (children in index order) — the order a
    BVH file lists its joints in."""
    par = np.asarray(parent, dtype=np.int64)
    kids: list[list[int]] = [[] for _ in range(par.size)]
    roots: list[int] = []
    for j, p in enumerate(par):
        (kids[int(p)] if p >= 0 else roots).append(j)
    out: list[int] = []
    stack = roots[::-1]
    while stack:
        j = stack.pop()
        out.append(j)
        stack.extend(kids[j][::-1])
    return np.asarray(out, dtype=np.int64)


def reorder_joints(
    skeleton: JointSkeleton, order: ArrayLike
) -> tuple[JointSkeleton, NDArray[np.int64]]:
    """The skeleton with joints permuted to ``order`` (new index -> old index), parents
    remapped; returns it and ``order`` for permuting per-joint arrays (``arr[:, order]``)."""
    order = np.asarray(order, dtype=np.int64)
    inv = np.empty_like(order)
    inv[order] = np.arange(order.size)
    par = skeleton.parent[order]
    par = np.where(par >= 0, inv[np.maximum(par, 0)], -1)
    sk = JointSkeleton(
        tuple(skeleton.names[i] for i in order),
        par,
        skeleton.offset[order],
        skeleton.rest_rotation[order],
        skeleton.limits[order],
        None if skeleton.channels is None else tuple(skeleton.channels[i] for i in order),
        skeleton.end_site[order],
    )
    return sk, order


def guess_up_axis(motion: Motion) -> str:
    """``"y"`` or ``"z"``: the axis along which the body stands highest above its feet.

    Feet are :func:`biomorph.core.names.foot_joints` (names, else the name preset; else the
    leaf joints). The body is the pelvis — the nearest joint above every foot — rather than
    the root: the same joint on most rigs, but a ground-level ``root`` of root motion stands
    *on* the floor and a creature skeleton's root is the front of its spine. The up axis is
    the one maximising the mean |pelvis - feet| over the clip (sampled to ~200 frames);
    ties (and skeletons without feet) give ``"y"``."""
    from biomorph.core.names import foot_joints
    from biomorph.core.skeleton import common_ancestor

    parent = motion.skeleton.parent
    feet = foot_joints(motion.names, parent)
    body = common_ancestor(parent, feet) if feet else 0
    if not feet:
        feet = list(np.setdiff1d(np.arange(motion.n_joints), parent))
    step = max(1, motion.n_frames // 200)
    pos = motion.world_positions(slice(None, None, step))
    d = np.abs(pos[:, body, :] - pos[:, feet, :].mean(axis=1)).mean(axis=0)
    return "z" if d[2] > 1.2 * d[1] and d[2] > d[0] else "y"


def preview_positions(motion: Motion, frame: int) -> tuple[Array, Array]:
    """World joint positions ``(n, 3)`` and bone segments ``(m, 2, 3)`` of one frame (for
    interactive viewers: cheap, one frame of FK)."""
    if not 0 <= frame < motion.n_frames:
        raise ParameterError(f"frame {frame} outside the clip; expected 0..{motion.n_frames - 1}")
    w = motion.world_matrices(slice(frame, frame + 1))[0]
    return w[:, :3, 3], motion.skeleton.bone_segments(w)


def transform_root(
    motion: Motion,
    rotation: ArrayLike,
    translation: ArrayLike = (0, 0, 0),
    pivot: ArrayLike = (0, 0, 0),
) -> Motion:
    """Apply the world transform ``p -> R (p - pivot) + pivot + translation`` to the motion.

    ``rotation`` is one quaternion ``(4,)`` or one per frame ``(f, 4)``; the root's
    orientation becomes ``R · orientation`` (pose rotation ``rest⁻¹ · R · rest · pose``)."""
    q = np.asarray(rotation, dtype=float)
    if q.shape not in ((4,), (motion.n_frames, 4)):
        raise ParameterError(
            f"root rotation has shape {q.shape}; expected (4,) or ({motion.n_frames}, 4)"
        )
    q = tf.quat_normalize(q)
    pivot = np.asarray(pivot, dtype=float)
    rest = motion.skeleton.rest_rotation[0]
    ident = np.array([0.0, 0.0, 0.0, 1.0])
    if q.shape == (4,) and np.array_equal(q, ident) and np.array_equal(rest, ident):
        # a pure translation of a root without rest rotation: R·v and rest⁻¹·I·rest·q are
        # exact identities (up to the sign of zeros), so the pose rotations are kept and the
        # rotation array shared instead of copied (blend's root alignment ends with one)
        pos = (motion.root_position - pivot) + pivot + np.asarray(translation, float)
        root = tf.quat_continuous(motion.rotation[:, 0], axis=0)
        rot = motion.rotation
        if not np.array_equal(root, rot[:, 0]):
            rot = np.array(rot)
            rot[:, 0] = root
    else:
        pos = tf.quat_rotate(q, motion.root_position - pivot) + pivot
        pos = pos + np.asarray(translation, float)
        rot = np.array(motion.rotation)
        root = tf.quat_multiply(
            tf.quat_conjugate(rest), tf.quat_multiply(q, tf.quat_multiply(rest, rot[:, 0]))
        )
        rot[:, 0] = tf.quat_continuous(root, axis=0)
    jt = None
    if motion.joint_translation is not None:
        jt = np.array(motion.joint_translation)
        jt[:, 0] = pos
    return motion.with_(
        rotation=frozen(rot), root_position=frozen(pos), joint_translation=frozen(jt)
    )


def to_y_up(motion: Motion, up: str = "z") -> Motion:
    """Convert a motion whose vertical axis is ``up`` to Y-up (``"y"`` returns it unchanged).

    Z-up → Y-up is a rotation of -90° about X: ``(x, y, z) -> (x, z, -y)``."""
    u = up.lower()
    if u == "y":
        return motion
    if u == "z":
        q = tf.quat_from_axis_angle("x", -np.pi / 2)
    elif u == "x":
        q = tf.quat_from_axis_angle("z", np.pi / 2)
    else:
        raise ParameterError(f"up axis {up!r}; expected 'x', 'y' or 'z'")
    out = transform_root(motion, q)
    meta = dict(out.meta)
    meta["up_converted_from"] = u
    meta["up_guess"] = "y"
    return out.with_(meta=meta)


# ---------------------------------------------------------------- compiled kernels
def ro(a: np.ndarray) -> np.ndarray:
    """A read-only, C-contiguous float64 view (or copy) of ``a`` for a kernel input.

    numba compiles one specialisation per array type, and read-only vs writable are different
    types: passing every input through ``ro`` keeps each kernel at a single compiled version
    (a cold cache compiles ``equalize_rotations`` once, ~8 s on a loaded machine, not twice).
    The caller's array is not touched (the flag is set on a new view)."""
    v = np.ascontiguousarray(a, dtype=np.float64).view()
    v.setflags(write=False)
    return v


def ro_int(a: np.ndarray) -> np.ndarray:
    """:func:`ro` for int64 index arrays."""
    v = np.ascontiguousarray(a, dtype=np.int64).view()
    v.setflags(write=False)
    return v


#: Joint-frames (frames × joints) from which the compiled kernels are used even when they
#: are not loaded yet. Measured with ``bench/cli.py --crossover`` (2-core VM, load 7.7):
#: importing numba and loading the cached kernels costs 0.6 s of CPU once per process; the
#: NumPy paths cost 0.30 µs (FK) and 0.15 µs (slerp) more per joint-frame than the compiled
#: ones, so they break even near 2 M and 4 M joint-frames. 1 M (a 2.3-minute 60-joint take
#: at 120 fps) keeps the NumPy path's extra cost below ~0.3 s.
COMPILED_MIN_WORK = 1_000_000


_numpy_work = [0]  #: joint-frames done by the NumPy paths in this process so far


def use_compiled(work: int) -> bool:
    """Whether to run a compiled kernel for ``work`` joint-frames: always once the kernels
    are loaded in this process (the studio, batch jobs, the operators); otherwise from
    :data:`COMPILED_MIN_WORK` on, for one call or summed over the calls so far (rent, then
    buy: a script calling FK on many clips pays at most about the kernels' load time in
    NumPy overhead before switching). Both paths give the same bits."""
    if (
        work >= COMPILED_MIN_WORK
        or _numpy_work[0] >= COMPILED_MIN_WORK
        or "biomorph.core._motion_kernels" in sys.modules
    ):
        return True
    _numpy_work[0] += work  # this call takes the NumPy path: count it
    return False


def _qmul_np(a: tuple[Array, ...], b: tuple[Array, ...]) -> tuple[Array, ...]:
    """Hamilton product of component tuples, the compiled ``_qmul``'s expression order."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    )


def fk_numpy(
    rest: Array, rot: Array, trans: Array, parent: ArrayLike, pos_out: Array, quat_out: Array
) -> None:
    """NumPy forward kinematics, vectorised over frames, joint by joint (parents first):
    the same arithmetic as ``_motion_kernels.fk_positions`` in the same order (same bits)."""
    par = np.asarray(parent, dtype=np.int64)
    for j in range(rot.shape[1]):
        r = rest[j]
        q = rot[:, j]
        loc = _qmul_np((r[0], r[1], r[2], r[3]), (q[:, 0], q[:, 1], q[:, 2], q[:, 3]))
        p = int(par[j])
        if p < 0:
            quat_out[:, j] = np.stack(loc, axis=-1)
            pos_out[:, j] = trans[:, j]
            continue
        pq = quat_out[:, p]
        px, py, pz, pw = pq[:, 0], pq[:, 1], pq[:, 2], pq[:, 3]
        quat_out[:, j] = np.stack(_qmul_np((px, py, pz, pw), loc), axis=-1)
        vx, vy, vz = trans[:, j, 0], trans[:, j, 1], trans[:, j, 2]
        tx = 2.0 * (py * vz - pz * vy)
        ty = 2.0 * (pz * vx - px * vz)
        tz = 2.0 * (px * vy - py * vx)
        pos_out[:, j, 0] = pos_out[:, p, 0] + (vx + pw * tx + (py * tz - pz * ty))
        pos_out[:, j, 1] = pos_out[:, p, 1] + (vy + pw * ty + (pz * tx - px * tz))
        pos_out[:, j, 2] = pos_out[:, p, 2] + (vz + pw * tz + (px * ty - py * tx))


def slerp_numpy(rot: Array, i0: NDArray[np.int64], frac: Array, out: Array) -> None:
    """NumPy ``_motion_kernels.sample_slerp``: ``out[k] = slerp(rot[i0[k]], rot[i0[k]+1],
    frac[k])``, exact at frac 0 and 1, hemisphere-continuous along k (same bits)."""
    a = rot[i0]
    b = rot[np.minimum(i0 + 1, rot.shape[0] - 1)]
    t = frac[:, None]
    d = a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]
    d = d + a[..., 3] * b[..., 3]
    neg = d < 0
    b = np.where(neg[..., None], -b, b)
    d = np.where(neg, -d, d)
    near = d > 0.9999999
    with np.errstate(invalid="ignore", divide="ignore"):
        th = _acos_libm(np.minimum(d, 1.0))
        s = np.sin(th)
        w0 = np.where(near, 1.0 - t, np.sin((1.0 - t) * th) / s)
        w1 = np.where(near, t, np.sin(t * th) / s)
    q = w0[..., None] * a + w1[..., None] * b
    n2 = q[..., 0] * q[..., 0] + q[..., 1] * q[..., 1] + q[..., 2] * q[..., 2]
    n = np.sqrt(n2 + q[..., 3] * q[..., 3])
    q = q / n[..., None]
    q = np.where((t == 1.0)[..., None], b, q)
    q = np.where((t == 0.0)[..., None], a, q)
    q[1:][_store_flips(np.sum(q[1:] * q[:-1], axis=-1))] *= -1.0
    out[...] = q


def _acos_libm(x: Array) -> Array:
    """``arccos`` by the C library's ``acos``, as the compiled kernels call it: NumPy's own
    SIMD ``arccos`` (AVX-512 builds) differs from it in the last bit on ~5 % of inputs, which
    would make the two paths' slerps differ by 1 ulp. About 60 ns per value, only on the
    NumPy (small-work) path."""
    flat = np.ravel(x)
    return np.fromiter(map(math.acos, flat.tolist()), np.float64, flat.size).reshape(x.shape)


def _store_flips(dots: Array) -> NDArray[np.bool_]:
    """Which samples the compiled ``_store_continuous`` negates, from the dot products of
    consecutive *unflipped* samples ``(f - 1, ...)``: it compares each sample with the stored
    (possibly negated) previous one, so the sign flips at every negative dot and resets to +
    at a dot of exactly 0 or NaN (``-0 < 0`` is false)."""
    neg = dots < 0
    count = np.cumsum(neg, axis=0)
    base = np.maximum.accumulate(np.where(neg | (dots > 0), 0, count), axis=0)
    return np.equal((count - base) % 2, 1)


__all__ = [
    "Motion",
    "MotionInputWarning",
    "tolerate",
    "concatenate",
    "dfs_preorder",
    "reorder_joints",
    "check_range",
    "same_skeleton",
    "guess_up_axis",
    "frozen",
    "preview_positions",
    "sample_arrays",
    "sample_linear",
    "transform_root",
    "to_y_up",
    "use_compiled",
    "ro",
    "ro_int",
    "ROTATION_CHANNELS",
    "POSITION_CHANNELS",
    "DEFAULT_ORDER",
]
