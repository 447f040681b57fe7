"""Partial-body operation (the seed's "Hierarchy Below"): an operator's result on one joint
and the hierarchy below it, the rest of the body from the base clip.

:func:`merge_below` keeps the base clip's length and timing; frame ``k`` of the subtree comes
from frame ``min(k, n_result - 1)`` of the result (a retimed or blended result shorter than
the base holds its last pose). Local rotations and translations of the chosen joints are
copied, so the subtree moves with the base clip's body above it.
"""

from __future__ import annotations

import numpy as np

from biomorph.core.motion import Motion, frozen, same_skeleton
from biomorph.errors import ParameterError


def subtree(motion: Motion, joint: str | int) -> np.ndarray:
    """Indices of ``joint`` and every joint below it."""
    sk = motion.skeleton
    if isinstance(joint, (int, np.integer)):
        if not 0 <= int(joint) < sk.n_joints:
            raise ParameterError(f"joint index {joint} outside 0..{sk.n_joints - 1}")
        j = int(joint)
    else:
        j = sk.index(joint)
    return np.asarray(sk.descendants(j), dtype=np.int64)


def merge_below(base: Motion, result: Motion, joint: str | int) -> Motion:
    """``base`` with ``joint`` and its hierarchy taken from ``result`` (module docstring)."""
    same_skeleton(base.skeleton, result.skeleton, "base and result")
    sel = subtree(base, joint)
    k = np.minimum(np.arange(base.n_frames), result.n_frames - 1)
    rot = np.array(base.rotation)
    rot[:, sel] = result.rotation[k][:, sel]
    pos = base.root_position
    jt = base.joint_translation
    if 0 in sel:
        pos = frozen(np.array(result.root_position[k]))
    if jt is not None or result.joint_translation is not None:
        jt = base.local_translations()
        jt[:, sel] = result.local_translations()[k][:, sel]
        jt[:, 0] = pos
    from biomorph.core import transforms as tf

    meta = dict(result.meta)
    meta["partial"] = {"joint": str(joint), "joints": int(sel.size)}
    return base.with_(
        rotation=frozen(tf.quat_continuous(rot, axis=0)),
        root_position=pos,
        joint_translation=jt,
        meta=meta,
    )


__all__ = ["merge_below", "subtree"]
