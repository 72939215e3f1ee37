"""A self-contained HTML viewer for a ``grasplan.grasps/1`` or ``grasplan.plan/1`` result.

:func:`build_html` returns ONE HTML document that works offline with no server: three.js (npm
``three@0.187.0`` with OrbitControls, bundled into ``three.iife.min.js``) and the page's script are
inlined, every mesh and pose is embedded as base64 Float32/Uint32 arrays, and a
Content-Security-Policy ``default-src 'none'`` forbids the page any request at all. Everything the
page shows is computed here, in Python (:func:`build_data`): the browser only plays back poses.
"""
from __future__ import annotations

import base64
import html
import json
import math
import os
import re
import warnings
import zlib
from collections.abc import Collection, Sequence
from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING, Any, cast

import numpy as np
from numpy.typing import ArrayLike, DTypeLike

from ..errors import InputError, MeshError
from ..io import write_atomic_text
from ..results.writer import GRASPS_SCHEMA, PLAN_SCHEMA
from ..status import Status
from ..geometry.transforms import pose7, quaternions

if TYPE_CHECKING:
    from ..cell.model import Cell
    from ..gripper.model import Shape
    from ..results.grasp_table import GraspTable
    from ..results.joint_motion import Motion
    from ..results.plan_result import PlanResult
    from ..robot.model import Robot

SCHEMAS = (GRASPS_SCHEMA, PLAN_SCHEMA)
#: display order (and drawing priority, last on top) of the statuses, with their colours
STATUS_COLORS: dict[str, str] = {s.value: c for s, c in (
    (Status.PLANNED, "#00c853"),
    (Status.OK, "#2e9d3a"),
    (Status.NOT_TRIED, "#9e9e9e"),
    (Status.NOT_CHECKED, "#cfd8dc"),
    (Status.NO_PATH, "#ab47bc"),
    (Status.IK_COLLISION, "#ffb300"),
    (Status.UNREACHABLE, "#fb8c00"),
    (Status.COLLISION_PART, "#e53935"),
    (Status.COLLISION_TABLE, "#1e88e5"),
    (Status.COLLISION_OBSTACLE, "#6d4c41"),
    (Status.PLACE_UNREACHABLE, "#f4511e"),
    (Status.PLACE_NO_PATH, "#8e24aa"),
)}
STATUS_ORDER = tuple(STATUS_COLORS)
OTHER_COLOR = "#607d8b"
#: largest joint step (rad) between two played-back samples of a path
PATH_STEP_RAD = 0.03
#: at most this many samples per planned path (the step grows when a path is longer)
MAX_SAMPLES_PER_PATH = 400
#: link meshes above this many triangles are decimated (vertex clustering)
MAX_LINK_TRIANGLES = 4000
#: a part above this many triangles is decimated for display (the page stays small)
MAX_PART_TRIANGLES = 250_000
#: grasp list: rows rendered per status before a "show more" button ...
LIST_CHUNK = 200
#: ... except for these statuses (the usable grasps), which are always listed in full
LIST_FULL = (Status.PLANNED.value, Status.OK.value)

_HERE = Path(__file__).resolve().parent


# --------------------------------------------------------------------------- encoding helpers
def encode_array(a: ArrayLike, dtype: DTypeLike) -> str:
    """Array -> base64 of its zlib-deflated little-endian bytes (the page inflates them with the
    browser's DecompressionStream('deflate'))."""
    raw = np.ascontiguousarray(np.asarray(a), dtype=dtype).tobytes()
    return base64.b64encode(zlib.compress(raw, 6)).decode("ascii")


def decimate_mesh(vertices: np.ndarray, faces: np.ndarray, max_faces: int) -> tuple[np.ndarray, np.ndarray]:
    """Vertex-clustering decimation to at most about ``max_faces`` triangles (display only).

    Vertices are snapped to a grid, merged per cell (mean position), and faces that collapse are
    dropped. The cell size grows until the face count fits. Returns ``(vertices (n', 3), faces (m', 3))``.
    """
    V = np.asarray(vertices, dtype=np.float64)
    F = np.asarray(faces, dtype=np.int64)
    if len(F) <= max_faces:
        return V, F
    ext = float(np.max(V.max(0) - V.min(0))) or 1.0
    cells = max(8, int(math.sqrt(max_faces) * 1.5))
    for _ in range(40):
        h = ext / cells
        key = np.floor((V - V.min(0)) / h).astype(np.int64)
        _, inv, counts = np.unique(key, axis=0, return_inverse=True, return_counts=True)
        inv = inv.reshape(-1)
        newV = np.zeros((len(counts), 3))
        np.add.at(newV, inv, V)
        newV /= counts[:, None]
        nF = inv[F]
        nF = nF[(nF[:, 0] != nF[:, 1]) & (nF[:, 1] != nF[:, 2]) & (nF[:, 0] != nF[:, 2])]  # collapsed
        _, first = np.unique(np.sort(nF, axis=1), axis=0, return_index=True)  # duplicates
        nF = nF[np.sort(first)]
        if len(nF) <= max_faces:
            used, remap = np.unique(nF, return_inverse=True)
            return newV[used], remap.reshape(-1, 3)
        cells = int(cells * 0.8)
    raise MeshError(f"cannot decimate a mesh of {len(F)} triangles to {max_faces}")


def mesh_block(vertices: ArrayLike, faces: ArrayLike) -> dict:
    V = np.asarray(vertices, dtype=np.float64)
    F = np.asarray(faces, dtype=np.int64)
    return {"v": encode_array(V.reshape(-1), "<f4"), "f": encode_array(F.reshape(-1), "<u4"), "nv": int(len(V)), "nf": int(len(F))}


# --------------------------------------------------------------------------- inputs
# --------------------------------------------------------------------------- gripper
def shape_json(shape: Shape, mesh_cache: dict, meshes: list) -> dict:
    """A gripper shape -> ``{"box": [ex, ey, ez], "pose": [7]}`` (a :class:`grasplan.gripper.Box`) or
    ``{"mesh": index, "pose": identity}`` (a ``MeshShape``, vertices already in the TCP frame)."""
    if hasattr(shape, "extents"):
        return {"box": [float(x) for x in np.asarray(shape.extents).reshape(3)],
                "pose": pose7(np.asarray(shape.T_tcp_box, dtype=np.float64),  # type: ignore[union-attr]  # a Box
                              order="xyzw").tolist()}
    if not (hasattr(shape, "vertices") and hasattr(shape, "faces")):
        raise InputError(f"cannot display gripper shape {type(shape).__name__}: neither a box nor a mesh")
    if id(shape) not in mesh_cache:
        V, F = decimate_mesh(np.asarray(shape.vertices), np.asarray(shape.faces), MAX_LINK_TRIANGLES)
        mesh_cache[id(shape)] = len(meshes)
        meshes.append(mesh_block(V, F))
    return {"mesh": mesh_cache[id(shape)], "pose": pose7(np.eye(4), order="xyzw").tolist()}


# --------------------------------------------------------------------------- robot
def _load_link_mesh(mesh_path: str, scale: ArrayLike) -> tuple[np.ndarray, np.ndarray] | None:
    import trimesh

    if not mesh_path or not os.path.isfile(mesh_path):
        return None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = trimesh.load(mesh_path, force="mesh", process=True)
    if not isinstance(m, trimesh.Trimesh) or len(m.faces) == 0:
        return None
    V = np.asarray(m.vertices, dtype=np.float64) * np.asarray(scale, dtype=np.float64).reshape(1, 3)
    return decimate_mesh(V, np.asarray(m.faces), MAX_LINK_TRIANGLES)


def densify_path(path: np.ndarray, *, step: float = PATH_STEP_RAD, max_samples: int = MAX_SAMPLES_PER_PATH
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Joint path (k, n) -> (samples (s, n), index of each original waypoint in the samples (k,)).

    The planner's densifier (:func:`grasplan.geometry.interpolation.interpolate_path`) at ``step`` rad per joint,
    the step grown so that s <= max_samples (when k <= max_samples).
    """
    from ..geometry.interpolation import interpolate_path

    P = np.asarray(path, dtype=np.float64)
    if P.ndim != 2 or len(P) == 0:
        raise InputError(f"a path must be a (k, n) list of joint vectors, got shape {P.shape}")
    total = float(np.abs(np.diff(P, axis=0)).max(axis=1).sum()) if len(P) > 1 else 0.0
    budget = max(max_samples - len(P), 0)
    if total > 0 and total / step > budget:
        step = total / max(budget, 1)
    return interpolate_path(P, step=step, return_index=True)


# --------------------------------------------------------------------------- page data
def build_data(res: PlanResult, *, part_path: str | os.PathLike[str] | None = None, allow_other_part: bool = False,
               blockers: Collection[str] = ()) -> tuple[dict, list[str]]:
    """Everything the page needs for a :class:`~grasplan.results.plan_result.PlanResult`, as one JSON-able dict
    (arrays base64-encoded), plus notes/warnings: the part mesh (at the result's ``scale_to_m``) and
    its pose ``T_world_part``; every grasp's world contact points and TCP pose ``T_world_part @
    T_part_tcp``; the gripper shapes in the TCP frame (the fingers at each grasp's pre-grasp opening);
    for a plan, the robot's meshes and every link's pose (Pinocchio) at q_home and along each path
    densified to at most :data:`PATH_STEP_RAD` per sample, with its segments and events
    (:func:`_robot_data`, :func:`_sequence_data`: no FK in JavaScript); the cell's obstacles and bin,
    drawn semi-transparent (:func:`cell_data`); per-grasp quality / simulation values when the
    result has them (:func:`_quality_data`). ``blockers``: the pile instances drawn as what blocked
    the pick (a pick's ``blocked_by``; every other instance is drawn neutral)."""
    notes: list[str] = _counted_note(res)
    schema = res.schema
    mesh = res.mesh(part_path, allow_other_part=allow_other_part)
    V = np.asarray(mesh.vertices, dtype=np.float64)
    F = np.asarray(mesh.faces, dtype=np.int64)
    if len(F) > MAX_PART_TRIANGLES:
        V, F = decimate_mesh(V, F, MAX_PART_TRIANGLES)
        notes.append(f"part decimated to {len(F)} triangles for display")
    T_world_part = res.T_world_part
    t = res.grasps
    n = len(t)
    gripper = res.gripper
    T_flange_tcp = gripper.T_flange_tcp

    # per-grasp arrays (vectorised: plan files can hold 10^5 grasps)
    statuses = t.status.astype(str)
    present = set(statuses.tolist())
    status_names = [s for s in STATUS_ORDER if s in present] + sorted(present - set(STATUS_ORDER))
    sidx = {s: i for i, s in enumerate(status_names)}
    st = np.zeros(n, dtype=np.uint8)
    for s_, i_ in sidx.items():
        st[statuses == s_] = i_
    ids = t.ids
    width = t.width
    contacts = t.contacts
    T_part_tcp = t.T_part_tcp
    score = t.score
    rk = np.flatnonzero(t.rank >= 0)
    ranks = dict(zip(map(str, rk.tolist()), t.rank[rk].tolist()))
    # contact pairs are shared by the roll variants of a candidate: store each pair once
    c_world = (contacts @ T_world_part[:3, :3].T + T_world_part[:3, 3]).reshape(n, 6).astype(np.float32)
    pairs, pair_of = np.unique(c_world, axis=0, return_inverse=True) if n else (np.zeros((0, 6), np.float32), np.zeros(0, np.int64))
    pair_of = pair_of.reshape(n)
    pair_width = np.zeros(len(pairs))
    pair_width[pair_of] = width
    pre_open = np.asarray(gripper.pregrasp_opening(pair_width), dtype=np.float64).reshape(len(pairs))
    # one marker per (contact pair, status): what is drawn
    marker = np.unique(np.stack([st.astype(np.int64), pair_of], 1), axis=0) if n else np.zeros((0, 2), np.int64)
    T_world_tcp = T_world_part[None] @ T_part_tcp if n else np.zeros((0, 4, 4))
    tcp_q = quaternions(T_world_tcp[:, :3, :3], order="xyzw") if n else np.zeros((0, 4))

    # gripper shapes: body once; fingers as a function of the opening (two openings -> linear in JS)
    gmeshes: list[dict] = []
    cache: dict = {}
    f_a = gripper.fingers(0.0)
    f_b = gripper.fingers(float(gripper.max_opening))
    grip = {
        "body": [shape_json(s, cache, gmeshes) for s in gripper.body],
        "fingers": [shape_json(s, cache, gmeshes) for s in f_a],  # at opening 0
        # the jaws translate with the opening: displacement of each jaw from opening 0 to max_opening
        "finger_shift": [(np.asarray(b.corners()).mean(0) - np.asarray(a.corners()).mean(0)).tolist()
                         for a, b in zip(f_a, f_b)],
        "max_opening": float(gripper.max_opening),
        "meshes": gmeshes,
        "name": gripper.name,
    }

    data: dict[str, Any] = {
        "schema": schema,
        "title": res.part.label,
        "part": {**mesh_block(V, F), "T_world_part": T_world_part.reshape(-1).tolist(), "path": res.part.path,
                 "scale_to_m": float(res.part.scale_to_m), "sha256": res.part.sha256},
        "cell": {"name": res.cell.name, "table_z": float(res.cell.table_z), **cell_data(res.cell, notes, blockers)},
        "statuses": [{"name": s, "color": STATUS_COLORS.get(s, OTHER_COLOR)} for s in status_names],
        "grasps": {
            "n": n,
            "id": encode_array(ids, "<i4"), "status": encode_array(st, "u1"), "score": encode_array(score, "<f4"), "rank": ranks,
            "pair": encode_array(pair_of, "<u4"),                       # contact pair of each grasp
            "pairs": encode_array(pairs, "<f4"), "npairs": int(len(pairs)),  # world contacts (p, 6)
            "width": encode_array(pair_width, "<f4"), "opening": encode_array(pre_open, "<f4"),  # per pair
            "marker_status": encode_array(marker[:, 0], "u1"), "marker_pair": encode_array(marker[:, 1], "<u4"),
            "tcp_p": encode_array(T_world_tcp[:, :3, 3], "<f4"),        # TCP position, world
            "tcp_q": encode_array(np.round(tcp_q * 32767), "<i2"),      # TCP quaternion (x, y, z, w) * 32767
        },
        "gripper": grip,
        "robot": None,
        "counts": {s: int((st == sidx[s]).sum()) for s in status_names},
        "list_chunk": LIST_CHUNK,
        "list_full": list(LIST_FULL),
    }

    q = _quality_data(t)
    if q:
        data["grasps"]["quality"] = q
    if res.robot is not None:
        data["robot"] = _robot_data(res, T_flange_tcp, notes)
    data["notes"] = notes
    return data, notes


def _counted_note(res: PlanResult) -> list[str]:
    """The note of a compact plan whose colliding poses are counts, not grasps to draw."""
    if res.rejected is None or not res.rejected.counts.sum():
        return []
    what = ", ".join(f"{k} {v}" for k, v in res.rejected.totals().items() if v)
    return [f"colliding poses are counted, not drawn ({what}): plan with --keep all to draw them"]


#: obstacle kinds the page draws (the cell JSON's shape keys)
OBSTACLE_KINDS = ("box", "cylinder", "sphere", "mesh")
#: how the page draws each obstacle role (:func:`obstacle_role`): fill colour, edge colour, legend text.
#: Red is kept for what blocked the pick (``blocked_by``); other pile instances are a neutral grey
OBSTACLE_ROLES: dict[str, tuple[str, str, str]] = {
    "blocker": ("#c62828", "#8e0000", "neighbour in the way (blocked_by)"),
    "neighbour": ("#90a4ae", "#546e7a", "other instance of the pile"),
    "obstacle": ("#ef6c00", "#a84300", "cell obstacle"),
    "bin": ("#8d6e63", "#5d4037", "bin floor and walls"),
}
#: obstacle name prefixes: the cell's bin walls and the pile's other instances (``instance_<id>``)
BIN_PREFIX, INSTANCE_PREFIX = "bin_", "instance_"


def obstacle_role(name: str, blockers: Collection[str] = ()) -> str:
    """``"bin"``, ``"blocker"`` (an instance named in ``blockers``), ``"neighbour"`` (another
    instance of a pile) or ``"obstacle"`` (the cell's own) for an obstacle called ``name``."""
    if name.startswith(BIN_PREFIX):
        return "bin"
    if name.startswith(INSTANCE_PREFIX):
        return "blocker" if name[len(INSTANCE_PREFIX):] in blockers else "neighbour"
    return "obstacle"


def cell_data(cell: Cell, notes: list[str], blockers: Collection[str] = ()) -> dict:
    """The cell's obstacles (from its JSON, so the page draws what the plan file holds) and bin:
    ``{"obstacles": [{"name", "kind", "role", "box": [sx, sy, sz] | "cylinder": [r, length] | "sphere": [r] |
    "mesh": {v, f, nv, nf}, "T": 16 row-major (T_world_obstacle)}], "bin": {...} | None,
    "roles": [{"role", "color", "edge", "label", "n"}]}``: ``role`` from :func:`obstacle_role`
    (``blockers``: the instance ids a pick's ``blocked_by`` names), ``roles`` the legend of the
    roles present, in :data:`OBSTACLE_ROLES` order."""
    doc = cell.to_json()
    out = []
    for i, ob in enumerate(doc.get("obstacles") or []):
        name = str(ob.get("name", f"obstacle {i}"))
        kind = next((k for k in OBSTACLE_KINDS if k in ob), None)
        T = np.asarray(ob.get("T_world_obstacle", np.eye(4)), dtype=np.float64)
        if kind is None or T.shape != (4, 4) or not np.all(np.isfinite(T)):
            notes.append(f"obstacle {name}: no drawable shape or pose; not shown")
            continue
        sh = ob[kind]
        e: dict[str, Any] = {"name": name, "kind": kind, "role": obstacle_role(name, blockers), "T": T.reshape(-1).tolist()}
        if kind == "box":
            e["box"] = [float(x) for x in sh["size"]]
        elif kind == "cylinder":
            e["cylinder"] = [float(sh["radius"]), float(sh["length"])]
        elif kind == "sphere":
            e["sphere"] = [float(sh["radius"])]
        else:
            V, F = decimate_mesh(np.asarray(sh["vertices"], dtype=np.float64), np.asarray(sh["faces"], dtype=np.int64),
                                 MAX_LINK_TRIANGLES)
            e["mesh"] = mesh_block(V, F)
        out.append(e)
    n_role = {r: sum(e["role"] == r for e in out) for r in OBSTACLE_ROLES}
    roles = [{"role": r, "color": c, "edge": edge, "label": label, "n": n_role[r]}
             for r, (c, edge, label) in OBSTACLE_ROLES.items() if n_role[r]]
    return {"obstacles": out, "bin": doc.get("bin"), "roles": roles}


def _quality_data(t: GraspTable) -> dict:
    """Per-grasp quality / simulation arrays of the grasp table when the result has
    them: ``gravity_margin``, ``epsilon`` (NaN: none), contact area (m^2) and type per jaw,
    simulation ``success`` (1 held, 0 slipped, -1 not simulated), slip (m), turn (deg)."""
    out: dict[str, Any] = {}
    n = len(t)
    for key in ("gravity_margin", "epsilon", "sim_slip_m", "sim_turn_deg"):
        a = getattr(t, key, None)
        if a is not None and len(a) == n:
            out[key] = encode_array(np.asarray(a, dtype=np.float64), "<f4")
    area = getattr(t, "contact_area", None)
    ctype = getattr(t, "contact_type", None)
    if area is not None and ctype is not None and len(area) == n:
        from ..results.quality_json import CONTACT_TYPES

        out["contact_area"] = encode_array(np.asarray(area, dtype=np.float64).reshape(n, 2), "<f4")
        out["contact_type"] = encode_array(np.asarray(ctype, dtype=np.int8).reshape(n, 2), "i1")
        out["contact_types"] = list(CONTACT_TYPES)
    succ = getattr(t, "sim_success", None)
    if succ is not None and len(succ) == n:
        out["sim_success"] = encode_array(np.asarray(succ, dtype=np.int8), "i1")
    return out


def _robot_data(res: PlanResult, T_flange_tcp: np.ndarray, notes: list[str]) -> dict:
    robot = cast("Robot", res.robot)  # the caller's test: a plan
    q_home = np.asarray(robot.q_home, dtype=np.float64)
    first = robot.link_poses(q_home)
    links: list[dict] = []
    meshes: list[dict] = []
    mesh_index: dict[tuple, int] = {}
    keep = []
    for k, (gname, _T, mpath, scale) in enumerate(first):
        key = (str(mpath), tuple(np.round(np.asarray(scale, dtype=float).reshape(-1), 9)))
        if key not in mesh_index:
            m = _load_link_mesh(str(mpath), scale)
            if m is None:
                if Path(str(mpath)).suffix:  # a mesh file that is missing (primitives have no suffix)
                    notes.append(f"robot geometry {gname}: mesh {mpath} not loadable; not shown")
                continue
            mesh_index[key] = len(meshes)
            meshes.append(mesh_block(*m))
        links.append({"name": str(gname), "mesh": mesh_index[key]})
        keep.append(k)

    def frames_of(qs: np.ndarray) -> np.ndarray:
        """(s, n) joint vectors -> (s, L + 1, 7) poses: the links, then the gripper TCP."""
        Ts = np.empty((len(qs), len(keep) + 1, 4, 4))
        for j, q in enumerate(qs):
            lp = robot.link_poses(q)
            for m, k in enumerate(keep):
                Ts[j, m] = lp[k][1]
            Ts[j, -1] = robot.fk(q) @ T_flange_tcp
        return pose7(Ts, order="xyzw")

    home = frames_of(q_home[None])[0]
    paths = {}
    chunks = [home.reshape(-1)]
    offset = 1  # in frames
    for gid in sorted(res.motions):
        motion = res.motions[gid]
        P = np.asarray(motion.path, dtype=np.float64)
        S, idx = densify_path(P)
        frames = frames_of(S)
        pre_s = int(idx[int(motion.pregrasp_index)])
        paths[str(gid)] = {"start": offset, "count": int(len(S)), "pregrasp": pre_s, "waypoints": int(len(P)),
                           **_sequence_data(res, gid, motion, idx)}
        chunks.append(frames.reshape(-1))
        offset += len(S)
    return {
        "name": robot.name,
        "joint_names": list(robot.joint_names),
        "links": links,
        "meshes": meshes,
        "frame_size": len(links) + 1,
        "frames": encode_array(np.concatenate(chunks), "<f4"),
        "paths": paths,
    }


def _sequence_data(res: PlanResult, gid: int, m: Motion, idx: np.ndarray) -> dict:
    """A path's segments and gripper events in played-back samples (``idx``: the sample of each
    path row), the jaw opening per phase and, for a pick(-and-place) plan, what the part does:
    ``attached`` = [close sample, open sample or null], ``T_tcp_part`` (part pose while attached =
    TCP @ T_tcp_part) and ``T_world_part_place`` (its pose after the release), 16 row-major. The
    page's part pose rule: at ``T_world_part`` until the close, ``TCP @ T_tcp_part`` while attached,
    ``T_world_part_place`` after the release."""
    from ..export.program import motion_segments

    g = res.grasp(gid)
    idx = np.asarray(idx, dtype=np.int64)
    segs = [{"label": str(a), "start": int(idx[s]), "end": int(idx[e])} for a, s, e in motion_segments(m)]
    events = [{"action": str(e.action), "width": float(e.width), "sample": int(idx[int(e.index)])}
              for e in getattr(m, "gripper", ())]
    out: dict[str, Any] = {"segments": segs, "events": events,
                           "opening": float(res.gripper.pregrasp_opening(g.width))}
    T_tcp_part = getattr(m, "T_tcp_part", None)
    close = next((e for e in events if e["action"] == "close"), None)
    if T_tcp_part is not None and close is not None:
        opened = next((e for e in events if e["action"] == "open"), None)
        out["attached"] = [close["sample"], None if opened is None else opened["sample"]]
        out["T_tcp_part"] = np.asarray(T_tcp_part, dtype=np.float64).reshape(-1).tolist()
        T_place = getattr(m, "T_world_part_place", None)
        if T_place is not None:
            out["T_world_part_place"] = np.asarray(T_place, dtype=np.float64).reshape(-1).tolist()
    return out


# --------------------------------------------------------------------------- HTML
def read_asset(name: str) -> str:
    try:
        return resources.files(__package__ or "grasplan.viewer").joinpath(name).read_text(encoding="utf-8")
    except (FileNotFoundError, AttributeError):
        return (_HERE / name).read_text(encoding="utf-8")


def script_safe(text: str) -> str:
    """Text that cannot end an inline <script> early."""
    return text.replace("</script", "<\\/script").replace("</SCRIPT", "<\\/SCRIPT")


def build_html(result: PlanResult | dict[str, Any] | str | os.PathLike[str], *,
               part_path: str | os.PathLike[str] | None = None, allow_other_part: bool = False,
               notes: Sequence[str] = (), blockers: Collection[str] = ()) -> str:
    """The viewer page for a grasps or plan result, as one HTML string (``notes``: lines shown under
    the page's summary, e.g. why a pile has no pick; ``blockers``: for a pick shown as a plan, the
    instance ids its ``blocked_by`` names, drawn red, every other instance neutral).

    Parameters
    ----------
    result : PlanResult, dict or path
        A :class:`~grasplan.results.plan_result.PlanResult`, or a grasps/plan document or file (read with
        :func:`grasplan.results.reader.load_result`: validated in full, models rebuilt from the file).
    part_path : path, optional
        The part's mesh file; default: the path recorded in the result (a relative path is looked
        up in the current folder, then next to the result file). Its sha256 must match the
        result's unless ``allow_other_part``.

    Raises
    ------
    InputError
        Not a grasps/plan document, the part cannot be found or differs, or a malformed grasp.
    """
    from ..results.reader import load_result

    res = load_result(result)
    data, found = build_data(res, part_path=part_path, allow_other_part=allow_other_part, blockers=blockers)
    for note in found:
        warnings.warn(note, stacklevel=2)
    data["notes"] = [*(str(n) for n in notes), *found]
    # every "<" escaped: no input string (a part or gripper name holding "</script>" or "<!--<script>")
    # can end the script block or switch the HTML parser's script state
    payload = json.dumps(data, separators=(",", ":"), allow_nan=False).replace("<", "\\u003c")
    template = read_asset("template.html")
    three = script_safe(read_asset("three.iife.min.js"))
    app = script_safe(read_asset("viewer.js"))
    css = read_asset("viewer.css")
    lic = html.escape(read_asset("THREE_LICENSE"))
    title = html.escape(f"grasplan view: {data['title']}")
    values = {"TITLE": title, "CSS": css, "THREE_LICENSE": lic, "DATA": payload, "THREE": three, "APP": app}
    missing = [k for k in values if "{{" + k + "}}" not in template]
    if missing:
        raise RuntimeError(f"viewer template lacks {missing}")
    # one pass: inserted text (three.js, the data) is never scanned for placeholders again
    return re.sub(r"\{\{([A-Z_]+)\}\}", lambda m: values[m.group(1)], template)


def write_viewer(result: PlanResult | dict[str, Any] | str | os.PathLike[str],
                 out_path: str | os.PathLike[str], *,
                 part_path: str | os.PathLike[str] | None = None, allow_other_part: bool = False, notes: Sequence[str] = (),
                 blockers: Collection[str] = ()) -> Path:
    """Write :func:`build_html`'s page atomically to ``out_path``; returns the path."""
    return write_atomic_text(out_path, build_html(result, part_path=part_path, allow_other_part=allow_other_part,
                                                  notes=notes, blockers=blockers))


__all__ = ["build_html", "write_viewer", "build_data", "densify_path", "decimate_mesh", "STATUS_COLORS",
           # the page-building pieces other pages share (the clutter replay, grasplan.clutter.replay)
           "encode_array", "mesh_block", "shape_json", "cell_data", "read_asset", "script_safe"]
