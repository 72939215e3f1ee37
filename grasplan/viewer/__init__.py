"""A self-contained HTML viewer for a ``grasplan.grasps/1`` or ``grasplan.plan/1`` result.

:func:`build_html` returns ONE HTML document that works offline with no server: three.js (npm
``three@0.187.0`` with OrbitControls, bundled into ``three.iife.min.js``) and the page's script are
inlined, every mesh and pose is embedded as base64 Float32/Uint32 arrays, and a
Content-Security-Policy ``default-src 'none'`` forbids the page any request at all.

What is computed here (Python), not in the browser:

- the part mesh (loaded with :func:`grasplan.mesh.load_part` at the result's ``scale_to_m``) and its
  cell pose ``T_world_part``;
- the contact points of every grasp in the world frame and the TCP pose ``T_world_tcp`` of every
  grasp (``T_world_part @ T_part_tcp``);
- the gripper boxes in the TCP frame (body, and the fingers at the pre-grasp opening of each grasp);
- for a plan: the robot's collision meshes (each embedded once, decimated when big) and the pose of
  every link, computed with Pinocchio, at q_home and along each planned path densified to at most
  :data:`PATH_STEP_RAD` per sample, so the browser only plays back poses (no FK in JavaScript).
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
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import GrasplanError, InputError, MeshError
from ..io import read_json, write_atomic_text
from ..transforms import check_transform, pose7, quaternions

SCHEMAS = ("grasplan.grasps/1", "grasplan.plan/1")
#: display order (and drawing priority, last on top) of the statuses, with their colours
STATUS_COLORS: dict[str, str] = {
    "planned": "#00c853",
    "ok": "#2e9d3a",
    "not_tried": "#9e9e9e",
    "no_path": "#ab47bc",
    "ik_collision": "#ffb300",
    "unreachable": "#fb8c00",
    "collision_part": "#e53935",
    "collision_table": "#1e88e5",
}
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
LIST_FULL = ("planned", "ok")

_HERE = Path(__file__).resolve().parent


# --------------------------------------------------------------------------- encoding helpers
def _enc(a, dtype) -> str:
    """Array -> base64 of its zlib-deflated little-endian bytes (the page inflates them with the
    browser's DecompressionStream('deflate'))."""
    raw = np.ascontiguousarray(np.asarray(a), dtype=dtype).tobytes()
    return base64.b64encode(zlib.compress(raw, 6)).decode("ascii")


def _field(grasps: list, key: str, shape: tuple, dtype) -> np.ndarray:
    """``grasps[i][key]`` for all i as one (n, *shape) array; InputError naming the first bad grasp."""
    try:
        a = np.array([g[key] for g in grasps], dtype=dtype)
        if a.shape == (len(grasps), *shape) and np.all(np.isfinite(a)):
            return a
    except (KeyError, TypeError, ValueError):
        pass
    for i, g in enumerate(grasps):
        try:
            v = np.asarray(g[key], dtype=dtype)
            ok = v.shape == shape and np.all(np.isfinite(v))
        except (KeyError, TypeError, ValueError):
            ok = False
        if not ok:
            raise InputError(f"grasps[{i}] (id {g.get('id')!r}): {key!r} missing or malformed; expected "
                             f"{'a number' if not shape else 'an array of shape ' + str(shape)}")
    raise InputError(f"grasps: {key!r} malformed")


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


def _mesh_block(vertices, faces) -> dict:
    V = np.asarray(vertices, dtype=np.float64)
    F = np.asarray(faces, dtype=np.int64)
    return {"v": _enc(V.reshape(-1), "<f4"), "f": _enc(F.reshape(-1), "<u4"), "nv": int(len(V)), "nf": int(len(F))}


# --------------------------------------------------------------------------- inputs
def _load_result(result_json) -> tuple[dict, Path | None]:
    if isinstance(result_json, dict):
        return result_json, None
    p = Path(result_json)
    if not p.exists():
        raise InputError(f"{p}: no such file")
    try:
        doc = read_json(p)
    except (OSError, ValueError) as exc:
        raise InputError(f"{p}: not a JSON file ({exc})") from exc
    if not isinstance(doc, dict):
        raise InputError(f"{p}: not a grasplan result (the JSON is not an object)")
    return doc, p.resolve().parent


def _check_doc(doc: dict, where: str) -> None:
    schema = doc.get("schema")
    if schema not in SCHEMAS:
        raise InputError(f"{where}: schema {schema!r} is not one the viewer shows; expected one of {', '.join(SCHEMAS)} "
                         f"(write one with `grasplan grasps` or `grasplan plan`)")
    for key in ("part", "grasps"):
        if key not in doc:
            raise InputError(f"{where}: the {schema} document has no {key!r} field")
    if not isinstance(doc["grasps"], list):
        raise InputError(f"{where}: 'grasps' must be a list")
    if "T_world_part" not in doc["part"]:
        raise InputError(f"{where}: part.T_world_part is missing")
    if schema == "grasplan.plan/1" and "robot" not in doc:
        raise InputError(f"{where}: a grasplan.plan/1 document needs a 'robot' block")


def _load_part_mesh(doc: dict, part_path, result_dir: Path | None) -> tuple[Path, np.ndarray, np.ndarray, list[str]]:
    """The result's part at its recorded scale (metres), decimated for display if large."""
    from ..mesh import load_recorded_part

    part = load_recorded_part(doc["part"], path=part_path, search_dirs=(result_dir,) if result_dir else ())
    V = np.asarray(part.vertices, dtype=np.float64)
    F = np.asarray(part.faces, dtype=np.int64)
    notes: list[str] = []
    sha = doc["part"].get("sha256")
    if sha and sha != part.sha256:
        notes.append(f"{part.path}: sha256 differs from the one recorded in the result ({part.sha256[:12]} vs {sha[:12]}); "
                     f"the grasps may not belong to this part")
    if len(F) > MAX_PART_TRIANGLES:
        V, F = decimate_mesh(V, F, MAX_PART_TRIANGLES)
        notes.append(f"part decimated to {len(F)} triangles for display")
    return Path(part.path), V, F, notes


# --------------------------------------------------------------------------- gripper
def _load_gripper(name: str | None, notes: list[str]):
    from ..gripper import load_gripper

    try:
        return load_gripper(name or "schunk_egp_c_40")
    except GrasplanError as exc:  # a result written with a gripper file this machine does not have
        notes.append(f"gripper {name!r} not loadable ({exc}); showing the default schunk_egp_c_40")
        return load_gripper("schunk_egp_c_40")


def _shape_json(shape, mesh_cache: dict, meshes: list) -> dict:
    """A gripper shape -> ``{"box": [ex, ey, ez], "pose": [7]}`` (a :class:`grasplan.gripper.Box`) or
    ``{"mesh": index, "pose": identity}`` (a ``MeshShape``, vertices already in the TCP frame)."""
    if hasattr(shape, "extents"):
        return {"box": [float(x) for x in np.asarray(shape.extents).reshape(3)],
                "pose": pose7(np.asarray(shape.T_tcp_box, dtype=np.float64), order="xyzw").tolist()}
    if not (hasattr(shape, "vertices") and hasattr(shape, "faces")):
        raise InputError(f"cannot display gripper shape {type(shape).__name__}: neither a box nor a mesh")
    if id(shape) not in mesh_cache:
        V, F = decimate_mesh(np.asarray(shape.vertices), np.asarray(shape.faces), MAX_LINK_TRIANGLES)
        mesh_cache[id(shape)] = len(meshes)
        meshes.append(_mesh_block(V, F))
    return {"mesh": mesh_cache[id(shape)], "pose": pose7(np.eye(4), order="xyzw").tolist()}


# --------------------------------------------------------------------------- robot
def _load_robot(doc: dict, notes: list[str]):
    from ..robot import load_robot

    rb = doc["robot"]
    robot = load_robot(rb.get("name", "ur5"))
    if list(rb.get("joint_names", robot.joint_names)) != list(robot.joint_names):
        raise InputError(f"robot.joint_names {rb.get('joint_names')} differ from robot {robot.name!r}'s "
                         f"{list(robot.joint_names)}; was the plan written for another robot description?")
    T = rb.get("T_world_base")
    if T is not None and not np.allclose(check_transform(T, "robot.T_world_base"), robot.T_world_base, atol=1e-9):
        notes.append("robot.T_world_base in the result differs from the robot's configuration; showing the configuration's")
    return robot


def _load_link_mesh(mesh_path: str, scale) -> tuple[np.ndarray, np.ndarray] | None:
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


def densify_path(path: np.ndarray, *, step: float = PATH_STEP_RAD, max_samples: int = MAX_SAMPLES_PER_PATH):
    """Joint path (k, n) -> (samples (s, n), index of each original waypoint in the samples (k,)).

    Linear interpolation in joint space (as the planner's checker does), at most ``step`` rad per
    joint between samples; the step grows so that s <= max_samples (when k <= max_samples).
    """
    P = np.asarray(path, dtype=np.float64)
    if P.ndim != 2 or len(P) == 0:
        raise InputError(f"a path must be a (k, n) list of joint vectors, got shape {P.shape}")
    d = np.abs(np.diff(P, axis=0)).max(axis=1) if len(P) > 1 else np.zeros(0)
    total = float(d.sum())
    budget = max(max_samples - len(P), 0)
    if total > 0 and total / step > budget:
        step = total / max(budget, 1)
    segs = np.maximum(np.ceil(d / step).astype(int), 1) if len(d) else np.zeros(0, dtype=int)
    out = [P[:1]]
    idx = [0]
    for i, n in enumerate(segs):
        t = (np.arange(1, n + 1) / n)[:, None]
        out.append(P[i] + t * (P[i + 1] - P[i]))
        idx.append(idx[-1] + int(n))
    return np.concatenate(out, axis=0), np.asarray(idx, dtype=np.int64)


# --------------------------------------------------------------------------- page data
def build_data(doc: dict, *, part_path=None, result_dir: Path | None = None) -> tuple[dict, list[str]]:
    """Everything the page needs, as one JSON-able dict (arrays base64-encoded), plus notes/warnings."""
    notes: list[str] = []
    _check_doc(doc, "result")
    schema = doc["schema"]
    ppath, V, F, pn = _load_part_mesh(doc, part_path, result_dir)
    notes += pn
    T_world_part = check_transform(doc["part"]["T_world_part"], "part.T_world_part")
    grasps = doc["grasps"]
    n = len(grasps)

    gr = doc.get("gripper", {}) or {}
    gripper = _load_gripper(gr.get("name"), notes)
    T_flange_tcp = check_transform(gr["T_flange_tcp"], "gripper.T_flange_tcp") if "T_flange_tcp" in gr else gripper.T_flange_tcp

    # per-grasp arrays (vectorised: plan files can hold 10^5 grasps)
    statuses = [str(g.get("status", "?")) for g in grasps]
    status_names = [s for s in STATUS_ORDER if s in set(statuses)] + sorted(set(statuses) - set(STATUS_ORDER))
    sidx = {s: i for i, s in enumerate(status_names)}
    st = np.array([sidx[s] for s in statuses], dtype=np.uint8).reshape(n)
    ids = _field(grasps, "id", (), np.int64)
    width = _field(grasps, "width", (), np.float64)
    contacts = _field(grasps, "contacts", (2, 3), np.float64)
    T_part_tcp = _field(grasps, "T_part_tcp", (4, 4), np.float64)
    score = np.array([np.nan if g.get("score") is None else float(g["score"]) for g in grasps], dtype=np.float64)
    ranks = {str(g["id"]): int(g["rank"]) for g in grasps if g.get("rank") is not None}
    if len(np.unique(ids)) != n:
        raise InputError("grasp ids are not unique")
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
        "body": [_shape_json(s, cache, gmeshes) for s in gripper.body],
        "fingers": [_shape_json(s, cache, gmeshes) for s in f_a],  # at opening 0
        # the jaws translate with the opening: displacement of each jaw from opening 0 to max_opening
        "finger_shift": [(np.asarray(b.corners()).mean(0) - np.asarray(a.corners()).mean(0)).tolist()
                         for a, b in zip(f_a, f_b)],
        "max_opening": float(gripper.max_opening),
        "meshes": gmeshes,
    }

    data: dict[str, Any] = {
        "schema": schema,
        "title": Path(str(doc["part"].get("path") or ppath)).name,
        "part": {**_mesh_block(V, F), "T_world_part": T_world_part.reshape(-1).tolist(), "path": str(ppath),
                 "scale_to_m": float(doc["part"].get("scale_to_m", 1.0))},
        "cell": {"name": (doc.get("cell") or {}).get("name", "table"),
                 "table_z": float((doc.get("cell") or {}).get("table_z", 0.0))},
        "statuses": [{"name": s, "color": STATUS_COLORS.get(s, OTHER_COLOR)} for s in status_names],
        "grasps": {
            "n": n,
            "id": _enc(ids, "<i4"), "status": _enc(st, "u1"), "score": _enc(score, "<f4"), "rank": ranks,
            "pair": _enc(pair_of, "<u4"),                       # contact pair of each grasp
            "pairs": _enc(pairs, "<f4"), "npairs": int(len(pairs)),  # world contacts (p, 6)
            "width": _enc(pair_width, "<f4"), "opening": _enc(pre_open, "<f4"),  # per pair
            "marker_status": _enc(marker[:, 0], "u1"), "marker_pair": _enc(marker[:, 1], "<u4"),
            "tcp_p": _enc(T_world_tcp[:, :3, 3], "<f4"),        # TCP position, world
            "tcp_q": _enc(np.round(tcp_q * 32767), "<i2"),      # TCP quaternion (x, y, z, w) * 32767
        },
        "gripper": grip,
        "robot": None,
        "counts": {s: int((st == sidx[s]).sum()) for s in status_names},
        "list_chunk": LIST_CHUNK,
        "list_full": list(LIST_FULL),
    }

    if schema == "grasplan.plan/1" and doc.get("robot"):
        data["robot"] = _robot_data(doc, grasps, ids, T_flange_tcp, notes)
    data["notes"] = notes
    return data, notes


def _robot_data(doc: dict, grasps: list, ids: np.ndarray, T_flange_tcp: np.ndarray, notes: list[str]) -> dict:
    rb = doc["robot"]
    robot = _load_robot(doc, notes)
    q_home = np.asarray(rb.get("q_home"), dtype=np.float64)
    first = robot.link_poses(q_home)
    links, meshes, mesh_index = [], [], {}
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
            meshes.append(_mesh_block(*m))
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
    for gid, g in zip(ids.tolist(), grasps):
        if g.get("status") != "planned" or not g.get("path"):
            continue
        P = np.asarray(g["path"], dtype=np.float64)
        S, idx = densify_path(P)
        frames = frames_of(S)
        pre = g.get("pregrasp_index")
        pre_s = int(idx[int(pre)]) if pre is not None and 0 <= int(pre) < len(idx) else None
        paths[str(gid)] = {"start": offset, "count": int(len(S)), "pregrasp": pre_s, "waypoints": int(len(P))}
        chunks.append(frames.reshape(-1))
        offset += len(S)
    return {
        "name": rb.get("name", "?"),
        "joint_names": list(rb.get("joint_names", [])),
        "links": links,
        "meshes": meshes,
        "frame_size": len(links) + 1,
        "frames": _enc(np.concatenate(chunks), "<f4"),
        "paths": paths,
    }


# --------------------------------------------------------------------------- HTML
def _read_asset(name: str) -> str:
    try:
        return resources.files(__name__).joinpath(name).read_text(encoding="utf-8")
    except (FileNotFoundError, AttributeError):
        return (_HERE / name).read_text(encoding="utf-8")


def _script_safe(text: str) -> str:
    """Text that cannot end an inline <script> early."""
    return text.replace("</script", "<\\/script").replace("</SCRIPT", "<\\/SCRIPT")


def build_html(result_json, *, part_path=None) -> str:
    """The viewer page for a ``grasplan.grasps/1`` or ``grasplan.plan/1`` result, as one HTML string.

    Parameters
    ----------
    result_json : dict or path
        The parsed result, or the path of its JSON file (then a relative ``part.path`` is looked up
        against the current folder, then the result file's folder).
    part_path : path, optional
        The part's mesh file; default: the path recorded in the result.

    Raises
    ------
    InputError
        Not a grasps/plan document, the part cannot be found, or a malformed grasp.
    """
    doc, result_dir = _load_result(result_json)
    data, notes = build_data(doc, part_path=part_path, result_dir=result_dir)
    for note in notes:
        if "sha256 differs" in note or "not loadable" in note:
            warnings.warn(note, stacklevel=2)
    payload = json.dumps(data, separators=(",", ":"), allow_nan=False).replace("</", "<\\/")
    template = _read_asset("template.html")
    three = _script_safe(_read_asset("three.iife.min.js"))
    app = _script_safe(_read_asset("viewer.js"))
    css = _read_asset("viewer.css")
    lic = html.escape(_read_asset("THREE_LICENSE"))
    title = html.escape(f"grasplan view: {data['title']}")
    values = {"TITLE": title, "CSS": css, "THREE_LICENSE": lic, "DATA": payload, "THREE": three, "APP": app}
    missing = [k for k in values if "{{" + k + "}}" not in template]
    if missing:
        raise RuntimeError(f"viewer template lacks {missing}")
    # one pass: inserted text (three.js, the data) is never scanned for placeholders again
    return re.sub(r"\{\{([A-Z_]+)\}\}", lambda m: values[m.group(1)], template)


def write_viewer(result_json, out_path, *, part_path=None) -> Path:
    """Write :func:`build_html`'s page atomically to ``out_path``; returns the path."""
    return write_atomic_text(out_path, build_html(result_json, part_path=part_path))


__all__ = ["build_html", "write_viewer", "build_data", "densify_path", "decimate_mesh", "STATUS_COLORS"]
