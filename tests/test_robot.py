"""Robot descriptions: loading, caching, errors, frames, and FK against an independent URDF chain."""
from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import FrozenInstanceError
from pathlib import Path

import numpy as np
import pytest

from grasplan.errors import ConfigError, InputError
from grasplan.robot.description import available_robots, load_robot, package_share_dir

ROBOTS = Path(__file__).resolve().parents[1] / "robots"


# ---- an independent forward kinematics: straight from the URDF XML, no Pinocchio -------------
def _rpy(r, p, y):
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    Rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    Ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    Rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def _axis_angle(axis, a):
    k = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(a) * K + (1 - math.cos(a)) * K @ K


def urdf_fk(urdf: Path, joint_values: dict[str, float], link: str) -> np.ndarray:
    """T_root_link from the URDF XML (fixed joints at 0, missing joint values at 0)."""
    root = ET.parse(urdf).getroot()
    by_child = {j.find("child").get("link"): j for j in root.findall("joint")}
    chain = []
    cur = link
    while cur in by_child:
        j = by_child[cur]
        chain.append(j)
        cur = j.find("parent").get("link")
    T = np.eye(4)
    for j in reversed(chain):
        o = j.find("origin")
        xyz = [float(v) for v in (o.get("xyz", "0 0 0") if o is not None else "0 0 0").split()]
        rpy = [float(v) for v in (o.get("rpy", "0 0 0") if o is not None else "0 0 0").split()]
        A = np.eye(4)
        A[:3, :3] = _rpy(*rpy)
        A[:3, 3] = xyz
        T = T @ A
        if j.get("type") in ("revolute", "continuous"):
            ax = [float(v) for v in j.find("axis").get("xyz").split()]
            M = np.eye(4)
            M[:3, :3] = _axis_angle(ax, joint_values.get(j.get("name"), 0.0))
            T = T @ M
    return T


# ---- loading ----------------------------------------------------------------------------------
def test_available_and_cached():
    assert {"ur5", "panda"} <= set(available_robots())
    r = load_robot("ur5")
    assert load_robot("ur5") is r
    assert load_robot(ROBOTS / "ur5.yaml") is load_robot(str(ROBOTS / "ur5.yaml"))


def test_unknown_robot_lists_available():
    with pytest.raises(ConfigError) as e:
        load_robot("ur6")
    assert "ur6" in str(e.value) and "panda" in str(e.value) and "ur5" in str(e.value)


def test_package_found_in_installed_files():
    share = package_share_dir()
    assert (share / "example-robot-data" / "robots" / "ur_description" / "urdf" / "ur5_robot.urdf").is_file()
    r = load_robot("ur5")
    assert r.urdf_path.is_file() and str(r.urdf_path).startswith(str(share))
    # never copied into the repo
    assert not list(ROBOTS.rglob("*.urdf")) and not list(ROBOTS.rglob("*.stl"))


@pytest.mark.parametrize("edit,field", [
    (lambda t: t.replace("q_home:", "q_hom:"), "q_hom"),
    (lambda t: "\n".join(l for l in t.splitlines() if not l.startswith("q_home")), "q_home"),
    (lambda t: t.replace("kind: ur ", "kind: scara "), "kind"),
    (lambda t: t.replace("tool_frame: tool0", "tool_frame: tool9"), "tool_frame"),
    (lambda t: t.replace("q_home: [0, -pi/2", "q_home: [0, -3*pi"), "q_home"),
    (lambda t: t.replace("q_home: [0, -pi/2", "q_home: [0, -pie/2"), "q_home"),
    (lambda t: t.replace("q_home: [0, -pi/2, pi/2, ", "q_home: [0, "), "q_home"),
    (lambda t: t.replace("mounted_links: [base_link", "mounted_links: [bass_link"), "mounted_links"),
    (lambda t: t.replace("urdf: ur_description/urdf/ur5_robot.urdf", "urdf: nothing.urdf"), "urdf"),
])
def test_malformed_file_names_the_field(tmp_path, edit, field):
    text = edit((ROBOTS / "ur5.yaml").read_text())
    p = tmp_path / "bad.yaml"
    p.write_text(text)
    with pytest.raises(ConfigError) as e:
        load_robot(p)
    assert field in str(e.value)


def test_robot_is_immutable():
    r = load_robot("ur5")
    with pytest.raises(FrozenInstanceError):
        r.name = "x"
    with pytest.raises(ValueError):
        r.q_home[0] = 1.0
    with pytest.raises(ValueError):
        r.lower[0] = 1.0


def test_ur5_description():
    r = load_robot("ur5")
    assert r.nq == 6 and r.kind == "ur" and r.tool_frame == "tool0"
    assert r.joint_names == ("shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint",
                             "wrist_1_joint", "wrist_2_joint", "wrist_3_joint")
    np.testing.assert_allclose(r.q_home, [0, -math.pi / 2, math.pi / 2, -math.pi / 2, -math.pi / 2, 0])
    # limits from the URDF
    np.testing.assert_allclose(r.upper, [2 * math.pi] * 2 + [math.pi] + [2 * math.pi] * 3, atol=1e-9)
    np.testing.assert_allclose(r.lower, -r.upper)
    np.testing.assert_allclose(r.velocity_limit, [3.15, 3.15, 3.15, 3.2, 3.2, 3.2])
    np.testing.assert_array_equal(r.T_world_base, np.eye(4))
    assert ("wrist_1_link", "wrist_2_link") in r.disabled_pairs
    assert r.mounted_links == ("base_link", "shoulder_link")
    with pytest.raises(InputError):
        r.fk(np.zeros(5))


def test_panda_description_without_hand():
    r = load_robot("panda")
    assert r.nq == 7 and r.tool_frame == "panda_link8"
    links = {r.link_name(g) for g in r.collision_model.geometryObjects}
    assert links == {f"panda_link{i}" for i in range(8)}
    assert not any("finger" in n or "hand" in n for n in r.joint_names)
    assert r.within_limits(r.q_home)
    np.testing.assert_allclose(r.lower[3], -3.0718) and np.testing.assert_allclose(r.upper[5], 3.7525)
    # the flange points down at home
    np.testing.assert_allclose(r.fk(r.q_home)[:3, 2], [0, 0, -1], atol=1e-3)


# ---- frames ------------------------------------------------------------------------------------
def test_ur5_frame_conventions():
    r = load_robot("ur5")
    rng = np.random.default_rng(3)
    for q in rng.uniform(r.lower, r.upper, size=(5, 6)):
        # base = base_link rotated 180 deg about z
        np.testing.assert_allclose(r.frame_pose(q, "base"), np.diag([-1.0, -1.0, 1.0, 1.0]), atol=1e-12)
        T_tool0, T_ee = r.fk(q), r.frame_pose(q, "ee_link")
        # tool0 and the ROS-I ee_link share the origin; tool0's z is ee_link's x (flange normal)
        np.testing.assert_allclose(T_tool0[:3, 3], T_ee[:3, 3], atol=1e-12)
        np.testing.assert_allclose(T_tool0[:3, 2], T_ee[:3, 0], atol=1e-12)
    # q_home: flange points straight down at the UR5's well-known home position
    T = r.fk(r.q_home)
    np.testing.assert_allclose(T[:3, 2], [0, 0, -1], atol=1e-9)
    # upper arm up, forearm forward along +x of base_link, wrist 2 pointing the flange down:
    # (a3 + d5, d4, d1 + a2 - d6) with the UR5's published DH lengths
    d1, a2, a3, d4, d5, d6 = 0.089159, 0.425, 0.39225, 0.10915, 0.09465, 0.0823
    np.testing.assert_allclose(T[:3, 3], [a3 + d5, d4, d1 + a2 - d6], atol=1e-9)


@pytest.mark.parametrize("name", ["ur5", "panda"])
def test_fk_matches_independent_urdf_chain(name):
    r = load_robot(name)
    tool_link = {"ur5": "tool0", "panda": "panda_link8"}[name]
    rng = np.random.default_rng(7)
    for q in rng.uniform(r.lower, r.upper, size=(25, r.nq)):
        T_ref = urdf_fk(r.urdf_path, dict(zip(r.joint_names, q)), tool_link)
        np.testing.assert_allclose(r.fk(q), r.T_world_base @ T_ref, atol=1e-10)


def test_fk_respects_T_world_base(tmp_path):
    T = np.eye(4)
    T[:3, :3] = _rpy(0.1, -0.2, 0.7)
    T[:3, 3] = [0.3, -0.1, 0.05]
    text = (ROBOTS / "ur5.yaml").read_text().replace("T_world_base: identity", f"T_world_base: {T.tolist()}")
    p = tmp_path / "ur5_moved.yaml"
    p.write_text(text)
    moved, ref = load_robot(p), load_robot("ur5")
    q = np.array([0.3, -1.0, 1.2, -0.4, 0.8, 2.0])
    np.testing.assert_allclose(moved.fk(q), T @ ref.fk(q), atol=1e-12)


@pytest.mark.parametrize("name", ["ur5", "panda"])
def test_link_poses_for_viewer(name):
    r = load_robot(name)
    q = r.q_home
    poses = r.link_poses(q)
    assert len(poses) == len(r.collision_model.geometryObjects)
    for gname, T, mesh, scale in poses:
        assert T.shape == (4, 4) and scale.shape == (3,)
        assert mesh == "" or Path(mesh).is_file()
    # a link's pose equals the independent URDF chain (no collision origin offsets in these URDFs)
    gname, T, mesh, _ = poses[2]
    link = gname.rsplit("_", 1)[0]
    np.testing.assert_allclose(T, urdf_fk(r.urdf_path, dict(zip(r.joint_names, q)), link), atol=1e-10)
    assert len(r.link_poses(q, which="visual")) >= 7


@pytest.mark.parametrize("name", ["ur5", "panda"])
def test_visual_geometry_is_built_on_first_use_and_equals_the_eager_build(name):
    """Loading a robot builds the collision geometry only (the visual meshes took 95 % of it);
    the visual geometry, built when asked for, equals pinocchio's eager build reduced the same way."""
    import pinocchio as pin

    from grasplan.robot.description import _build_robot, _resolve

    r = _build_robot(_resolve(name)[1])  # a fresh build (load_robot's cache may hold a used one)
    assert r._visual == []  # not built by loading
    v = r.visual_model
    assert r.visual_model is v  # built once
    full, _, vfull = pin.buildModelsFromUrdf(str(r.urdf_path), list(r.package_dirs))
    kept = {str(f.name) for f in r.model.frames}
    names = sorted(str(g.name) for g in vfull.geometryObjects if str(full.frames[g.parentFrame].name) in kept)
    assert sorted(str(g.name) for g in v.geometryObjects) == [n for n in names if n in {str(g.name) for g in v.geometryObjects}]
    assert len(v.geometryObjects) > 0
    # every visual object hangs off a frame of the (reduced) model the planner uses
    assert all(0 <= g.parentFrame < r.model.nframes for g in v.geometryObjects)
    lp = r.link_poses(r.q_home, which="visual")
    assert len(lp) == len(v.geometryObjects) and all(np.all(np.isfinite(T)) for _, T, _, _ in lp)
