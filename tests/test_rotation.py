"""companion.domain.rotation against scipy's Rotation (the reference), and its forms against each other."""

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from companion.domain import rotation as rot


def _random(n: int, seed: int = 7) -> np.ndarray:
    return Rotation.random(n, random_state=np.random.default_rng(seed)).as_quat(scalar_first=True)


def test_matrix_is_scipys_and_block_equals_single_bit_for_bit():
    q = _random(50)
    block = rot.rotation_matrix(q)
    np.testing.assert_allclose(block, Rotation.from_quat(q, scalar_first=True).as_matrix(), atol=1e-15)
    for k in range(len(q)):
        assert (rot.rotation_matrix(q[k]) == block[k]).all()  # the same expression, element by element
        assert rot.rotation_terms(*q[k].tolist()) == tuple(block[k].ravel())


def test_unnormalised_forms_agree():
    q = _random(20) * np.random.default_rng(1).uniform(0.5, 3.0, (20, 1))
    n, unit = rot.normalised(*q.T, sqrt=np.sqrt)
    np.testing.assert_allclose(n, np.linalg.norm(q, axis=1), rtol=1e-15)
    expect = Rotation.from_quat(np.column_stack(unit), scalar_first=True).as_matrix().reshape(-1, 9)
    np.testing.assert_allclose(np.column_stack(rot.rotation_ned_frd(*q.T, np.sqrt)), expect, atol=1e-15)
    s = 2.0 / np.sum(q * q, axis=1)
    np.testing.assert_allclose(np.column_stack(rot.rotation_scaled(*q.T, s)), expect, atol=1e-15)


@pytest.mark.parametrize("roll, pitch, yaw", [(0.1, -0.2, 2.5), (-3.0, 1.2, -1.0), (0.0, 0.0, -math.pi / 2)])
def test_euler_round_trip_is_scipys_zyx(roll, pitch, yaw):
    q = rot.euler_to_quaternion(roll, pitch, yaw)
    x, y, z, w = Rotation.from_euler("ZYX", [yaw, pitch, roll]).as_quat()
    np.testing.assert_allclose(q, (w, x, y, z), atol=1e-15)
    np.testing.assert_allclose(rot.quaternion_to_euler(q), (roll, pitch, yaw), atol=1e-12)
    assert rot.yaw_of(np.array(q)) == rot.quaternion_to_euler(q)[2]
    assert rot.quaternion_to_euler(np.array(q, dtype=np.float32)) == rot.quaternion_to_euler(
        [float(c) for c in np.array(q, dtype=np.float32)])  # computed in float64 whatever the input
