"""The twin's quaternion boundary: MuJoCo reads the shared helper's (w, x, y, z) as the same rotation."""

import mujoco
import numpy as np
from scipy.spatial.transform import Rotation

from tlt_common.geometry.transforms import rotation_to_mujoco_quat


def test_mujoco_reads_the_shared_quaternion_as_the_rotation_it_came_from():
    for rot in Rotation.random(50, rng=5).as_matrix():
        quat = rotation_to_mujoco_quat(rot)
        back = np.zeros(9)
        mujoco.mju_quat2Mat(back, quat)
        assert np.allclose(back.reshape(3, 3), rot, atol=1e-12)
        own = np.zeros(4)
        mujoco.mju_mat2Quat(own, rot.reshape(9))
        assert np.allclose(quat, own, atol=1e-12) or np.allclose(quat, -own, atol=1e-12)
