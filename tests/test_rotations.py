"""Quaternion, matrix and 6-D utilities: algebraic properties and numpy/torch agreement."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from habitsim import rotations as R
from habitsim.models import kinematics as K

quat_arrays = arrays(
    np.float64, (4,), elements=st.floats(-1, 1, allow_nan=False, allow_infinity=False)
).filter(lambda q: np.linalg.norm(q) > 0.1)


def _rand_quats(n: int, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return R.quat_normalize(rng.normal(size=(n, 4)))


def test_rotation_about_y_by_hand() -> None:
    # 90 deg about +y maps +x to -z and -z to -x (a downward bone swings backward).
    q = R.rot_y(np.pi / 2)
    np.testing.assert_allclose(R.quat_apply(q, [1.0, 0, 0]), [0, 0, -1], atol=1e-12)
    np.testing.assert_allclose(R.quat_apply(q, [0, 0, -1.0]), [-1, 0, 0], atol=1e-12)
    # 90 deg about +z maps +x to +y.
    np.testing.assert_allclose(R.quat_apply(R.rot_z(np.pi / 2), [1.0, 0, 0]), [0, 1, 0], atol=1e-12)


@settings(max_examples=60, deadline=None)
@given(quat_arrays, quat_arrays)
def test_product_matches_matrix_product(a: np.ndarray, b: np.ndarray) -> None:
    a, b = R.quat_normalize(a), R.quat_normalize(b)
    np.testing.assert_allclose(
        R.quat_to_matrix(R.quat_mul(a, b)), R.quat_to_matrix(a) @ R.quat_to_matrix(b), atol=1e-12
    )


@settings(max_examples=60, deadline=None)
@given(quat_arrays)
def test_inverse_and_norm(q: np.ndarray) -> None:
    q = R.quat_normalize(q)
    ident = R.quat_mul(q, R.quat_conj(q))
    np.testing.assert_allclose(np.abs(ident), [1, 0, 0, 0], atol=1e-12)
    v = np.array([0.3, -1.2, 2.0])
    assert np.linalg.norm(R.quat_apply(q, v)) == pytest.approx(np.linalg.norm(v))


def test_matrix_and_6d_round_trips() -> None:
    q = _rand_quats(200)
    q2 = R.matrix_to_quat(R.quat_to_matrix(q))
    np.testing.assert_allclose(R.quat_angle(q, q2), 0.0, atol=1e-6)
    q3 = R.sixd_to_quat(R.quat_to_6d(q))
    np.testing.assert_allclose(R.quat_angle(q, q3), 0.0, atol=1e-6)
    # 6-D of a matrix holds exactly its first two columns.
    m = R.quat_to_matrix(q[0])
    np.testing.assert_allclose(R.matrix_to_6d(m), np.r_[m[:, 0], m[:, 1]])


def test_axis_angle_and_euler() -> None:
    q = R.quat_from_axis_angle([0, 0, 1], 0.7)
    np.testing.assert_allclose(R.quat_to_axis_angle(q), [0, 0, 0.7], atol=1e-12)
    # Intrinsic ZXY: R = Rz(a) Rx(b) Ry(c).
    a, b, c = 0.3, -0.5, 1.1
    q = R.euler_to_quat(np.array([a, b, c]), "ZXY")
    expect = R.quat_mul(R.quat_mul(R.rot_z(a), R.rot_x(b)), R.rot_y(c))
    assert R.quat_angle(q, expect) < 1e-9
    np.testing.assert_allclose(R.quat_to_euler(q, "ZXY"), [a, b, c], atol=1e-9)


def test_slerp_midpoint_and_continuity() -> None:
    a, b = R.rot_z(0.0), R.rot_z(1.0)
    mid = R.quat_slerp(a, b, 0.5)
    assert R.quat_angle(mid, R.rot_z(0.5)) < 1e-9
    q = np.stack([R.rot_z(0.1), -R.rot_z(0.2), R.rot_z(0.3)])
    fixed = R.quat_fix_continuity(q)
    assert np.all(np.sum(fixed[1:] * fixed[:-1], axis=-1) > 0)


def test_zero_quaternion_rejected() -> None:
    with pytest.raises(ValueError, match="zero-norm"):
        R.quat_normalize(np.zeros(4))


def test_torch_agrees_with_numpy() -> None:
    a, b = _rand_quats(64, 1), _rand_quats(64, 2)
    v = np.random.default_rng(3).normal(size=(64, 3))
    ta, tb, tv = (torch.tensor(x) for x in (a, b, v))
    np.testing.assert_allclose(K.torch_quat_mul(ta, tb).numpy(), R.quat_mul(a, b), atol=1e-12)
    np.testing.assert_allclose(K.torch_quat_apply(ta, tv).numpy(), R.quat_apply(a, v), atol=1e-12)
    np.testing.assert_allclose(K.torch_quat_to_matrix(ta).numpy(), R.quat_to_matrix(a), atol=1e-12)
    m = torch.tensor(R.quat_to_matrix(a))
    back = K.torch_sixd_to_matrix(K.torch_matrix_to_6d(m))
    np.testing.assert_allclose(back.numpy(), m.numpy(), atol=1e-9)
    q_back = K.torch_matrix_to_quat(m).numpy()
    np.testing.assert_allclose(R.quat_angle(q_back, a), 0.0, atol=1e-6)
