"""URScript program for one planned grasp (Universal Robots arms only).

The program (one ``def grasplan_pick(): ... end``, the form the controller runs when the file is
sent to its script port or loaded by ``ur_robot_driver``):

1. ``grasplan_open_gripper(opening)`` / ``grasplan_close_gripper(width)``: defined at the top, with
   placeholder bodies (a ``textmsg`` and a ``sleep``). **Fill them in** with your gripper's I/O.
2. ``set_tcp(p[...])``: the gripper's ``T_flange_tcp`` (flange = URDF ``tool0``).
3. ``movej([...], a=, v=)`` to every waypoint of the planned joint path from ``q_home`` to
   ``q_pregrasp`` without blending (``movej`` moves on a straight line in joint space, which is how
   the planner verified the path; a blend radius would cut corners).
4. ``movel(p[x, y, z, rx, ry, rz], a=, v=)``: the straight approach to the grasp TCP.
5. close the gripper; ``movel`` straight back to the pre-grasp pose (the retreat).

Poses are in the controller's base frame, which is the URDF frame ``base`` (rotated 180 deg about z
from ``base_link`` in the UR description). It is read from the Pinocchio model's frames:
``T_base_tcp = inv(T_world_base @ T_root_base) @ T_world_part @ T_part_tcp`` where ``T_world_base``
is the plan's ``robot.T_world_base`` (world -> model root) and ``T_root_base`` the pose of frame
``base`` in the model. Rotations are rotation vectors (axis * angle, rad). Lengths in metres.

Before writing, the grasp is cross-checked with forward kinematics: ``FK(q_grasp) @ T_flange_tcp``
must equal the grasp TCP (1 mm, 0.01 rad); otherwise the plan belongs to another robot or gripper.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from ..errors import InputError
from . import grasp_arrays, select_grasp

#: joint order of every UR arm (URScript's joint vector order)
UR_JOINTS = ("shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint",
             "wrist_1_joint", "wrist_2_joint", "wrist_3_joint")

#: URScript defaults: joint moves (rad/s, rad/s^2) and the linear approach/retreat (m/s, m/s^2)
JOINT_SPEED = 1.05
JOINT_ACCEL = 1.4
LINEAR_SPEED = 0.05
LINEAR_ACCEL = 0.5
#: FK cross-check tolerances (m, rad)
POS_TOL = 1e-3
ROT_TOL = 1e-2


def rotvec(R: np.ndarray) -> np.ndarray:
    """Rotation vector (3,) of a rotation matrix (3, 3), robust near pi (via the quaternion)."""
    U, _, Vt = np.linalg.svd(np.asarray(R, dtype=np.float64))
    R = U @ np.diag([1.0, 1.0, np.linalg.det(U @ Vt)]) @ Vt  # nearest rotation
    return Rotation.from_matrix(R).as_rotvec()


def pose_vector(T: np.ndarray) -> np.ndarray:
    """URScript pose ``[x, y, z, rx, ry, rz]`` (6,) of a transform (4, 4)."""
    return np.concatenate([T[:3, 3], rotvec(T[:3, :3])])


def fmt_list(v, digits: int = 6) -> str:
    return "[" + ", ".join(f"{x:.{digits}f}" for x in np.asarray(v, dtype=float)) + "]"


def fmt_pose(T: np.ndarray) -> str:
    return "p" + fmt_list(pose_vector(T))


def _robot(plan_json: dict, robot):
    if robot is None:
        from ..robot import load_robot

        robot = load_robot(plan_json["robot"]["name"])
    return robot


def _frame_pose(model, data, name: str) -> np.ndarray | None:
    if not model.existFrame(name):
        return None
    return data.oMf[model.getFrameId(name)].homogeneous.copy()


def base_and_tcp_poses(plan_json: dict, g: dict, robot) -> dict[str, np.ndarray]:
    """Poses for the program: T_urbase_tcp (grasp), T_urbase_pre (FK of q_pregrasp), T_flange_tcp.

    Also cross-checks ``FK(q_grasp)`` against the grasp TCP; :class:`InputError` when they differ.
    """
    import pinocchio as pin

    a = grasp_arrays(plan_json, g)
    model = robot.model
    data = model.createData()
    tool = getattr(robot, "tool_frame", None) or "tool0"
    if not model.existFrame(tool):
        raise InputError(f"robot {plan_json['robot']['name']!r} has no frame {tool!r} (the UR flange)")
    T_world_root = np.asarray(plan_json["robot"]["T_world_base"], dtype=np.float64)
    T_flange_tcp = np.asarray(plan_json["gripper"]["T_flange_tcp"], dtype=np.float64)

    pin.framesForwardKinematics(model, data, np.zeros(model.nq))
    T_root_base = _frame_pose(model, data, "base")
    if T_root_base is None:  # a UR model without the controller's frame: the UR convention
        T_root_base = _frame_pose(model, data, "base_link")
        if T_root_base is None:
            T_root_base = np.eye(4)
        T_root_base = T_root_base @ np.diag([-1.0, -1.0, 1.0, 1.0])
    T_world_urbase = T_world_root @ T_root_base
    T_urbase_world = np.linalg.inv(T_world_urbase)

    def fk_tcp(q):
        pin.framesForwardKinematics(model, data, np.asarray(q, dtype=np.float64))
        return T_world_root @ data.oMf[model.getFrameId(tool)].homogeneous @ T_flange_tcp

    T_world_tcp = a["T_world_tcp"]
    T_fk = fk_tcp(a["q_grasp"])
    dp = float(np.linalg.norm(T_fk[:3, 3] - T_world_tcp[:3, 3]))
    dr = float(np.linalg.norm(rotvec(T_fk[:3, :3].T @ T_world_tcp[:3, :3])))
    if dp > POS_TOL or dr > ROT_TOL:
        raise InputError(f"grasp {g['id']}: FK(q_grasp) is {dp * 1000:.1f} mm / {dr:.3f} rad away from the grasp TCP "
                         f"with robot {plan_json['robot']['name']!r}; the plan was made with another robot or gripper")
    return {
        "T_urbase_tcp": T_urbase_world @ T_world_tcp,
        "T_urbase_pre": T_urbase_world @ fk_tcp(a["q_pregrasp"]),
        "T_flange_tcp": T_flange_tcp,
        "T_world_urbase": T_world_urbase,
        "path": a["path"],
        "pregrasp_index": a["pregrasp_index"],
    }


def urscript_program(plan_json: dict, *, grasp_id: int | None = None, robot=None, source: str | None = None,
                     joint_speed: float = JOINT_SPEED, joint_accel: float = JOINT_ACCEL,
                     linear_speed: float = LINEAR_SPEED, linear_accel: float = LINEAR_ACCEL) -> str:
    """The URScript program text for ``grasp_id`` (default: the best planned grasp)."""
    names = tuple(plan_json["robot"]["joint_names"])
    if names != UR_JOINTS:
        raise InputError(f"URScript runs only on Universal Robots arms; robot {plan_json['robot']['name']!r} has joints "
                         f"{', '.join(names)}. Export a joint trajectory instead: --format joint-trajectory")
    for name, v in (("joint_speed", joint_speed), ("joint_accel", joint_accel),
                    ("linear_speed", linear_speed), ("linear_accel", linear_accel)):
        if not (np.isfinite(v) and v > 0):
            raise InputError(f"{name} must be > 0, got {v!r}")
    g = select_grasp(plan_json, grasp_id)
    robot = _robot(plan_json, robot)
    P = base_and_tcp_poses(plan_json, g, robot)
    width = float(g["width"])
    max_opening = float(plan_json["gripper"]["max_opening"])
    opening = min(max_opening, width + 0.010)
    k = P["pregrasp_index"]
    moves = P["path"][: k + 1]
    a, v = f"{joint_accel:g}", f"{joint_speed:g}"
    la, lv = f"{linear_accel:g}", f"{linear_speed:g}"
    part = plan_json["part"]

    L: list[str] = []
    L += [
        f"# grasplan: pick program for grasp {g['id']} (status planned, score {g.get('score')}, rank {g.get('rank')})",
        f"# plan: {source or '(in memory)'}; part: {part['path']} (sha256 {part['sha256'][:16]}..., "
        f"scale_to_m {part['scale_to_m']:g}: file units -> metres)",
        f"# robot: {plan_json['robot']['name']}; gripper: {plan_json['gripper']['name']}; "
        f"grasp width {width * 1000:.2f} mm, pre-grasp opening {opening * 1000:.2f} mm",
        "# Units: metres, radians. Poses p[x, y, z, rx, ry, rz] are in the controller's base frame",
        "# (URDF frame 'base'); rx, ry, rz is a rotation vector. Joint order: base, shoulder, elbow,",
        "# wrist 1, wrist 2, wrist 3.",
        "# The joint path was verified collision-free with straight-line joint interpolation between",
        "# waypoints: keep the movej calls unblended (no r=) so the robot stays on it.",
        "def grasplan_pick():",
        "  # ---- Gripper I/O: FILL THESE IN for your gripper --------------------------------------",
        "  # grasplan cannot know how your gripper is wired. Replace each body with your gripper's",
        "  # commands, e.g. a tool digital output   set_tool_digital_out(0, True)   or a URCap call,",
        "  # and return only when the jaws have finished moving.",
        "  def grasplan_open_gripper(opening):",
        "    # open the jaws to at least `opening` metres (the pre-grasp opening)",
        "    textmsg(\"grasplan: fill in grasplan_open_gripper(); opening [m] = \", opening)",
        "    sleep(0.5)",
        "  end",
        "  def grasplan_close_gripper(width):",
        "    # close the jaws on the part; `width` is the part's width between the contacts, metres",
        "    textmsg(\"grasplan: fill in grasplan_close_gripper(); width [m] = \", width)",
        "    sleep(0.5)",
        "  end",
        "  # ----------------------------------------------------------------------------------------",
        f"  # TCP = flange (URDF tool0) * T_flange_tcp of gripper {plan_json['gripper']['name']!r}",
        f"  set_tcp({fmt_pose(P['T_flange_tcp'])})",
        f"  grasplan_open_gripper({opening:.6f})",
        f"  # joint path: q_home -> q_pregrasp ({len(moves)} waypoints)",
    ]
    for i, q in enumerate(moves):
        tag = "q_home" if i == 0 else ("q_pregrasp" if i == len(moves) - 1 else f"waypoint {i}")
        L.append(f"  movej({fmt_list(q)}, a={a}, v={v})  # {tag}")
    L += [
        "  # straight approach to the grasp TCP (jaws open)",
        f"  movel({fmt_pose(P['T_urbase_tcp'])}, a={la}, v={lv})  # grasp",
        f"  grasplan_close_gripper({width:.6f})",
        "  # straight retreat to the pre-grasp pose",
        f"  movel({fmt_pose(P['T_urbase_pre'])}, a={la}, v={lv})  # pre-grasp",
        "end",
    ]
    return "\n".join(L) + "\n"
