"""TCP frames from contact pairs: axes, roll sweep, no duplicates, rigid-motion invariance."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from grasplan.candidates.antipodal_base import Candidates
from grasplan.grasps.frames import grasp_frames, roll_angles, unique_pairs


def box_candidates(size=(0.03, 0.02, 0.01)) -> Candidates:
    """Contacts on opposite faces of a box centred at the origin (one pair per axis)."""
    h = np.asarray(size) / 2
    contacts, normals = [], []
    for k in range(3):
        e = np.zeros(3)
        e[k] = 1.0
        contacts.append([-h[k] * e, h[k] * e])
        normals.append([-e, e])
    contacts = np.array(contacts)
    return Candidates(contacts, np.array(normals), np.linalg.norm(contacts[:, 1] - contacts[:, 0], axis=1),
                      np.arange(6, dtype=np.int64).reshape(3, 2))


def test_roll_angles():
    assert len(roll_angles(15)) == 24
    assert len(roll_angles(25)) == 15 and np.degrees(roll_angles(25)[-1]) == pytest.approx(350)
    assert len(roll_angles(360)) == 1
    with pytest.raises(ValueError):
        roll_angles(0)


def test_axes_origin_and_roll():
    c = box_candidates()
    fr = grasp_frames(c, roll_step_deg=15)
    assert fr.T_part_tcp.shape == (72, 4, 4) and fr.candidate.dtype == np.int64
    T = fr.T_part_tcp
    R = T[:, :3, :3]
    np.testing.assert_allclose(R @ np.swapaxes(R, 1, 2), np.broadcast_to(np.eye(3), R.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)
    np.testing.assert_allclose(T[:, 3], np.broadcast_to([0, 0, 0, 1.0], (72, 4)))
    cont = c.contacts[fr.candidate]
    np.testing.assert_allclose(T[:, :3, 3], cont.mean(axis=1), atol=1e-15)
    x = (cont[:, 1] - cont[:, 0]) / c.width[fr.candidate][:, None]
    np.testing.assert_allclose(R[:, :, 0], x, atol=1e-12)
    np.testing.assert_allclose(np.cross(R[:, :, 2], R[:, :, 0]), R[:, :, 1], atol=1e-12)  # y = z x x
    # roll: angle between z(roll) and z(0) about x equals roll
    z0 = R[fr.roll == 0][:, :, 2]
    for k in range(3):
        sel = fr.candidate == k
        zs = R[sel][:, :, 2]
        ang = np.arctan2(np.einsum("ij,ij->i", np.cross(z0[k], zs), R[sel][:, :, 0]), zs @ z0[k]) % (2 * np.pi)
        np.testing.assert_allclose(ang, fr.roll[sel], atol=1e-9)
    # roll 0 approaches along the reference (part -z) when x is perpendicular to it
    np.testing.assert_allclose(R[(fr.candidate == 0) & (fr.roll == 0)][0][:, 2], [0, 0, -1], atol=1e-12)


def test_swapped_and_repeated_candidates_are_posed_once():
    c = box_candidates()
    swapped = Candidates(c.contacts[:, ::-1], c.normals[:, ::-1], c.width, c.faces[:, ::-1])
    both = Candidates(*(np.concatenate([getattr(c, f), getattr(swapped, f), getattr(c, f)[:1]])
                        for f in ("contacts", "normals", "width", "faces")))
    keep = unique_pairs(both)
    assert keep.tolist() == [True] * 3 + [False] * 4
    fr = grasp_frames(both, roll_step_deg=30)
    assert len(fr) == 3 * 12
    # every (closing line, approach) pose is distinct even when x -> -x is identified
    key = np.round(np.concatenate([np.abs(fr.T_part_tcp[:, :3, 0]), fr.T_part_tcp[:, :3, 2],
                                   fr.T_part_tcp[:, :3, 3]], axis=1), 9)
    assert len(np.unique(key, axis=0)) == len(fr)
    # an asymmetric gripper keeps both closing directions
    assert len(grasp_frames(both, roll_step_deg=30, dedupe_swapped=False)) == 7 * 12


def test_max_width_filter():
    c = box_candidates()
    fr = grasp_frames(c, roll_step_deg=90, max_width=0.025)
    assert set(fr.candidate.tolist()) == {1, 2}


def test_empty():
    fr = grasp_frames(Candidates.empty())
    assert fr.T_part_tcp.shape == (0, 4, 4) and len(fr) == 0


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_frames_follow_rigid_motion(seed):
    """Moving the part (and the reference with it) moves every frame rigidly."""
    rng = np.random.default_rng(seed)
    c = box_candidates(rng.uniform(0.005, 0.05, 3))
    T = np.eye(4)
    T[:3, :3] = Rotation.random(random_state=seed).as_matrix()
    T[:3, 3] = rng.uniform(-1, 1, 3)
    ref = np.array([0.3, -0.2, -1.0])
    a = grasp_frames(c, roll_step_deg=45, reference=ref)
    b = grasp_frames(c.transformed(T), roll_step_deg=45, reference=T[:3, :3] @ ref)
    np.testing.assert_allclose(T @ a.T_part_tcp, b.T_part_tcp, atol=1e-9)
