"""Property tests for core.transforms: 4x4 algebra, quaternions, Euler orders vs scipy."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.spatial.transform import Rotation

from biomorph.core import transforms as tf
from biomorph.errors import ParameterError

finite = st.floats(-10, 10, allow_nan=False, allow_infinity=False)
vec3 = arrays(np.float64, 3, elements=finite)
quat_raw = arrays(np.float64, 4, elements=st.floats(-1, 1, allow_nan=False)).filter(
    lambda q: np.linalg.norm(q) > 1e-3
)
angles = arrays(np.float64, 3, elements=st.floats(-np.pi, np.pi, allow_nan=False))
SETTINGS = settings(max_examples=60, deadline=None)
pytestmark = pytest.mark.filterwarnings("ignore:Gimbal lock detected:UserWarning")


def unit(q):
    return q / np.linalg.norm(q)


def rigid(q, t):
    return tf.make_transform(unit(q), t)


def same_rotation(a, b, atol=1e-9):
    return np.allclose(tf.quat_to_matrix(a), tf.quat_to_matrix(b), atol=atol)


@SETTINGS
@given(quat_raw, vec3, quat_raw, vec3, vec3)
def test_compose_apply_matches_sequential_application(q1, t1, q2, t2, p):
    a, b = rigid(q1, t1), rigid(q2, t2)
    assert np.allclose(tf.apply(tf.compose(a, b), p), tf.apply(a, tf.apply(b, p)), atol=1e-9)


@SETTINGS
@given(quat_raw, vec3, arrays(np.float64, 3, elements=st.floats(0.2, 5)))
def test_invert_and_invert_rigid(q, t, scale):
    r = rigid(q, t)
    assert np.allclose(tf.compose(r, tf.invert_rigid(r)), np.eye(4), atol=1e-9)
    assert np.allclose(tf.invert_rigid(r), tf.invert(r), atol=1e-9)
    s = r.copy()
    s[:3, :3] = s[:3, :3] * scale  # non-rigid: only the general inverse applies
    assert np.allclose(tf.invert(s) @ s, np.eye(4), atol=1e-8)


@SETTINGS
@given(quat_raw, vec3, quat_raw, vec3)
def test_local_from_world_recovers_local(q1, t1, q2, t2):
    parent, local = rigid(q1, t1), rigid(q2, t2)
    child = parent @ local
    assert np.allclose(tf.local_from_world(parent, child), local, atol=1e-9)


def test_make_transform_batches_and_identity():
    t = tf.make_transform(tf.quat_identity((5,)), np.arange(15.0).reshape(5, 3))
    assert t.shape == (5, 4, 4)
    assert np.allclose(t[:, :3, :3], np.eye(3))
    assert np.allclose(t[:, :3, 3], np.arange(15.0).reshape(5, 3))
    assert np.allclose(tf.compose(), np.eye(4))


@SETTINGS
@given(quat_raw, vec3)
def test_quat_rotate_matches_matrix_and_scipy(q, v):
    q = unit(q)
    m = tf.quat_to_matrix(q)
    assert np.allclose(tf.quat_rotate(q, v), m @ v, atol=1e-9)
    assert np.allclose(m, Rotation.from_quat(q).as_matrix(), atol=1e-9)
    back = tf.matrix_to_quat(m)
    assert back[3] >= 0 and same_rotation(back, q)


@SETTINGS
@given(quat_raw, quat_raw, vec3)
def test_quat_multiply_is_composition(a, b, v):
    a, b = unit(a), unit(b)
    ab = tf.quat_multiply(a, b)
    assert np.allclose(tf.quat_rotate(ab, v), tf.quat_rotate(a, tf.quat_rotate(b, v)), atol=1e-9)
    assert np.allclose(tf.quat_multiply(a, tf.quat_conjugate(a)), [0, 0, 0, 1], atol=1e-12)


@pytest.mark.parametrize("order", tf.EULER_ORDERS)
@SETTINGS
@given(a=angles)
def test_euler_to_quat_agrees_with_scipy_intrinsic(order, a):
    q = tf.euler_to_quat(a, order)
    ref = Rotation.from_euler(order.upper(), a).as_matrix()
    assert np.allclose(tf.quat_to_matrix(q), ref, atol=1e-9)
    # BVH meaning: R = R_order[0](a0) @ R_order[1](a1) @ R_order[2](a2)
    mats = [tf.rotation_about_axis(ax.lower(), a[i]) for i, ax in enumerate(order)]
    assert np.allclose(tf.quat_to_matrix(q), mats[0] @ mats[1] @ mats[2], atol=1e-9)


@pytest.mark.parametrize("order", tf.EULER_ORDERS)
@SETTINGS
@given(q=quat_raw)
def test_quat_euler_round_trip(order, q):
    q = unit(q)
    e = tf.quat_to_euler(q, order)
    assert np.all(np.abs(e[1]) <= np.pi / 2 + 1e-9)
    assert same_rotation(tf.euler_to_quat(e, order), q, atol=1e-7)
    deg = tf.quat_to_euler(q, order, degrees=True)
    assert np.allclose(np.deg2rad(deg), e)
    assert same_rotation(tf.euler_to_quat(deg, order, degrees=True), q, atol=1e-7)


@pytest.mark.parametrize("order", tf.EULER_ORDERS)
def test_quat_to_euler_matches_scipy_and_holds_at_gimbal_lock(order):
    """The NumPy decomposition equals scipy's away from lock, rebuilds the rotation to
    rounding near lock (where scipy loses 1e-9), and is its own fixed point at lock."""
    rng = np.random.default_rng(7)
    q = unit(rng.standard_normal((2000, 4)))
    e = tf.quat_to_euler(q, order)
    d = np.abs(e - Rotation.from_quat(q).as_euler(order))
    assert np.minimum(d, 2 * np.pi - d).max() < 1e-12
    ang = rng.uniform(-np.pi, np.pi, (400, 3))
    ang[:, 1] = (
        np.pi / 2 * np.sign(rng.standard_normal(400)) * (1 - np.repeat([0, 1e-4, 3e-3, 1e-9], 100))
    )
    q_lock = tf.euler_to_quat(ang, order)
    e_lock = tf.quat_to_euler(q_lock, order)
    assert np.abs(e_lock[:, 1]).max() <= np.pi / 2
    near = slice(100, 300)
    assert same_rotation(tf.euler_to_quat(e_lock[near], order), q_lock[near], atol=1e-12)
    assert same_rotation(tf.euler_to_quat(e_lock, order), q_lock, atol=1e-8)
    exact = slice(0, 100)
    assert np.allclose(e_lock[exact, 2], 0.0, atol=1e-12)  # at lock c = 0 (scipy's choice)
    again = tf.quat_to_euler(tf.euler_to_quat(e_lock[exact], order), order)
    assert np.allclose(again, e_lock[exact], atol=1e-9)


def test_euler_rejects_unknown_order():
    with pytest.raises(ParameterError, match="XXY"):
        tf.euler_to_quat([0, 0, 0], "XXY")
    with pytest.raises(ParameterError):
        tf.quat_to_euler([0, 0, 0, 1], "ABC")


@SETTINGS
@given(quat_raw, quat_raw, st.floats(0, 1))
def test_slerp_endpoints_unit_norm_and_constant_speed(a, b, t):
    a, b = unit(a), unit(b)
    assert np.allclose(tf.quat_slerp(a, b, 0.0), a, atol=1e-9)
    end = tf.quat_slerp(a, b, 1.0)
    assert same_rotation(end, b, atol=1e-7)
    q = tf.quat_slerp(a, b, t)
    assert np.isclose(np.linalg.norm(q), 1.0)
    total = tf.quat_angle(a, b)
    assert np.isclose(tf.quat_angle(a, q), t * total, atol=1e-6)
    assert np.isclose(tf.quat_angle(q, b), (1 - t) * total, atol=1e-6)


def test_slerp_broadcasts_over_time():
    a = tf.quat_identity()
    b = tf.quat_from_axis_angle("z", np.pi / 2)
    ts = np.linspace(0, 1, 11)
    qs = tf.quat_slerp(a, b, ts)
    assert qs.shape == (11, 4)
    assert np.allclose(tf.quat_angle(a, qs), ts * np.pi / 2, atol=1e-9)


@SETTINGS
@given(
    arrays(np.float64, (20, 4), elements=st.floats(-1, 1, allow_nan=False)).filter(
        lambda q: (np.linalg.norm(q, axis=1) > 1e-3).all()
    ),
    arrays(np.bool_, 20),
)
def test_continuity_fixes_hemisphere_without_changing_rotations(q, flips):
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    noisy = np.where(flips[:, None], -q, q)
    cont = tf.quat_continuous(noisy)
    assert np.all(np.sum(cont[1:] * cont[:-1], axis=1) >= 0)
    assert np.allclose(cont[0], noisy[0])
    assert np.allclose(np.abs(np.sum(cont * q, axis=1)), 1.0)  # same rotations
    # along another axis (time = axis 1)
    cont2 = tf.quat_continuous(noisy[None], axis=1)
    assert np.allclose(cont2[0], cont)


@SETTINGS
@given(arrays(np.float64, 3, elements=st.floats(-3, 3, allow_nan=False)))
def test_rotvec_round_trip(r):
    if np.linalg.norm(r) >= np.pi - 1e-6:
        return  # log map returns the angle in [0, pi]
    q = tf.quat_from_rotvec(r)
    assert np.isclose(np.linalg.norm(q), 1.0)
    assert np.allclose(tf.quat_to_rotvec(q), r, atol=1e-9)
    assert np.allclose(Rotation.from_rotvec(r).as_quat(), q * np.sign(q[3] or 1), atol=1e-9)


def test_rotvec_small_angles_exact():
    r = np.array([1e-14, -2e-14, 3e-15])
    assert np.allclose(tf.quat_to_rotvec(tf.quat_from_rotvec(r)), r, rtol=1e-6, atol=0)


def test_axis_angle_and_normalize():
    q = tf.quat_from_axis_angle([0, 0, 2.0], np.pi)
    assert np.allclose(q, [0, 0, 1, 0], atol=1e-12)
    qs = tf.quat_from_axis_angle("x", np.array([0.0, np.pi / 2]))
    assert qs.shape == (2, 4)
    with pytest.raises(ParameterError):
        tf.quat_from_axis_angle("w", 1.0)
    with pytest.raises(ParameterError):
        tf.quat_normalize([0, 0, 0, 0])
    assert np.allclose(tf.quat_normalize([0, 0, 0, 2]), [0, 0, 0, 1])


def test_unwrap_euler_removes_jumps():
    a = np.deg2rad(np.array([[170.0], [179.0], [-179.0], [-170.0]]))
    u = tf.unwrap_euler(a)
    assert np.all(np.diff(u[:, 0]) > 0) and np.all(np.abs(np.diff(u[:, 0])) < 0.2)
    d = tf.unwrap_euler(np.array([170.0, -170.0]), degrees=True)
    assert np.allclose(d, [170, 190])
