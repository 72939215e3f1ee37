"""The HTML viewer: page content checked statically, and rendered in headless Chromium.

Browser tests (marked ``browser``) open the page with Debian's ``chromium`` (installed by .ci/run)
in headless mode with SwiftShader GL and no network, and check (1) a screenshot: the 3D canvas is
drawn, not blank; (2) the DOM after the first frame: every planned grasp is listed with its
``data-grasp-id`` and the page reports a rendered frame; (3) no network request: statically (no
external URL in src/href/import/fetch, no <link>/<script src>) and dynamically (a CSP that forbids
every request, and the page still renders with every host name unresolvable).
"""
from __future__ import annotations

import json
import re
import shutil
import struct
import subprocess
import zlib
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest

from grasplan.errors import InputError
from grasplan.part.mesh import load_part
from grasplan.results.reader import load_result
from grasplan.viewer.page import (
    OTHER_COLOR,
    STATUS_COLORS,
    build_data,
    build_html,
    decimate_mesh,
    densify_path,
    write_viewer,
)

ROOT = Path(__file__).resolve().parents[1]
BRACKET = ROOT / "examples" / "parts" / "bracket.stl"
CHROMIUM = shutil.which("chromium") or ("/usr/bin/chromium" if Path("/usr/bin/chromium").exists() else None)
needs_chromium = pytest.mark.skipif(CHROMIUM is None, reason="headless Chromium not installed (apt-get install chromium; .ci/run does)")

CANVAS_X0 = 341  # the side panel is 340 px wide; the 3D canvas fills the rest of the 1280x800 window
CANVAS_Y0, CANVAS_Y1 = 200, 760  # rows checked: below an error banner (top), above the help line (bottom)


# ----------------------------------------------------------------------------- synthetic results
def _ik(robot, T_world_tool, q0, iters=300):
    """Damped least squares on the tool frame (independent of grasplan.robot.ik)."""
    import pinocchio as pin

    model, data = robot.model, robot.model.createData()
    target = pin.SE3(np.linalg.inv(robot.T_world_base) @ T_world_tool)
    q = np.array(q0, dtype=float)
    for _ in range(iters):
        pin.forwardKinematics(model, data, q)
        M = pin.updateFramePlacement(model, data, robot.tool_frame_id)
        err = pin.log6(M.actInv(target)).vector
        if np.linalg.norm(err) < 1e-9:
            break
        J = pin.computeFrameJacobian(model, data, q, robot.tool_frame_id, pin.LOCAL)
        q = pin.integrate(model, q, J.T @ np.linalg.solve(J @ J.T + 1e-6 * np.eye(6), err))
    assert np.allclose(robot.fk(q), T_world_tool, atol=1e-6), "synthetic plan: IK did not converge"
    return q


def _first_hits(mesh, origins: np.ndarray, d: np.ndarray) -> np.ndarray:
    """First intersection of each ray origins[i] + t d (t > 0) with the mesh (Moeller-Trumbore,
    vectorised over faces); (k, 3), NaN where the ray misses."""
    tri = mesh.triangles
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    pvec = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, pvec)
    out = np.full((len(origins), 3), np.nan)
    ok = np.abs(det) > 1e-15
    for k, o in enumerate(origins):
        tvec = o - tri[:, 0]
        u = np.einsum("ij,ij->i", tvec, pvec) / np.where(ok, det, 1)
        qvec = np.cross(tvec, e1)
        v = (qvec @ d) / np.where(ok, det, 1)
        t = np.einsum("ij,ij->i", e2, qvec) / np.where(ok, det, 1)
        hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
        if hit.any():
            out[k] = o + t[hit].min() * d
    return out


def synthetic_result(part_path: Path, *, units="mm", n_planned=3, plan=True, seed=0, max_grasps=None) -> dict:
    """A grasps/plan document on a real part: top-down grasps whose contacts come from ray casts
    along the part's x axis (so they lie on the surface), statuses drawn at random, and real
    q_grasp/q_pregrasp/paths (Pinocchio IK) for the planned ones. Self-contained like grasplan's
    own files: the gripper's definition, the whole cell and the robot's source are embedded."""
    from grasplan.cell.model import load_cell
    from grasplan.gripper.load import load_gripper
    from grasplan.robot.description import load_robot

    rng = np.random.default_rng(seed)
    part = load_part(part_path, units=units)
    mesh = part.mesh
    lo, hi = mesh.bounds
    T_world_part = np.eye(4)
    T_world_part[:3, 3] = [0.45 - (lo[0] + hi[0]) / 2, 0.0 - (lo[1] + hi[1]) / 2, -lo[2]]
    ys = np.linspace(lo[1], hi[1], 14)[1:-1]
    zs = np.linspace(lo[2], hi[2], 8)[1:-1]
    Y, Z = np.meshgrid(ys, zs)
    starts = np.stack([np.full(Y.size, lo[0] - 0.01), Y.ravel(), Z.ravel()], 1)
    ends = starts.copy()
    ends[:, 0] = hi[0] + 0.01
    a = _first_hits(mesh, starts, np.array([1.0, 0, 0]))
    b = _first_hits(mesh, ends, np.array([-1.0, 0, 0]))
    gripper = load_gripper("schunk_egp_c_40")
    grasps = []
    statuses = ["collision_part", "collision_table", "unreachable", "ik_collision", "no_path", "not_tried"] if plan \
        else ["ok", "collision_part", "collision_table"]
    for ray in np.flatnonzero(np.isfinite(a[:, 0]) & np.isfinite(b[:, 0])):
        p0, p1 = a[ray], b[ray]
        w = float(p1[0] - p0[0])
        if not 0.002 < w <= gripper.max_opening:
            continue
        mid = (p0 + p1) / 2
        for roll in np.radians([-30.0, -15.0, 0.0, 15.0, 30.0]):
            c, s = np.cos(roll), np.sin(roll)
            R0 = np.array([[1.0, 0, 0], [0, -1.0, 0], [0, 0, -1.0]])  # x = closing, z = down
            Rx = np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
            T = np.eye(4)
            T[:3, :3] = R0 @ Rx
            T[:3, 3] = mid
            grasps.append({"id": len(grasps), "candidate": int(ray), "contacts": [p0.tolist(), p1.tolist()],
                           "normals": [[-1.0, 0, 0], [1.0, 0, 0]], "width": w, "T_part_tcp": T.tolist(),
                           "roll": float(roll), "status": str(rng.choice(statuses)),
                           "score": float(rng.uniform(0, 1)), "rank": None})
    if max_grasps is not None:
        grasps = grasps[:max_grasps]
    doc = {"schema": "grasplan.plan/1" if plan else "grasplan.grasps/1",
           "part": {**part.to_json(), "T_world_part": T_world_part.tolist()},
           "gripper": gripper.to_json(definition=True), "cell": dict(load_cell("table").to_json(), part_pose="given"),
           "counts": {}, "timing_s": {}, "grasps": grasps}
    if not plan:
        return doc
    robot = load_robot("ur5")
    doc["robot"] = robot.to_json(source=True)
    Tinv = np.linalg.inv(gripper.T_flange_tcp)
    best = sorted(range(len(grasps)), key=lambda i: -grasps[i]["score"])
    for rank, i in enumerate(best[:n_planned], start=1):
        g = grasps[i]
        T_world_tcp = T_world_part @ np.asarray(g["T_part_tcp"])
        T_pre = T_world_tcp.copy()
        T_pre[:3, 3] -= 0.05 * T_world_tcp[:3, 2]
        q_pre = _ik(robot, T_pre @ Tinv, robot.q_home)
        q_grasp = _ik(robot, T_world_tcp @ Tinv, q_pre)
        q_mid = (robot.q_home + q_pre) / 2 + np.array([0, -0.3, 0, 0, 0, 0])
        g.update(status="planned", rank=rank, q_grasp=q_grasp.tolist(), q_pregrasp=q_pre.tolist(),
                 path=[robot.q_home.tolist(), q_mid.tolist(), q_pre.tolist(), q_grasp.tolist()], pregrasp_index=2)
    return doc


# ----------------------------------------------------------------------------- headless Chromium
def run_chromium(page: Path, tmp: Path, *args: str, timeout: float = 120.0, fragment: str = "",
                 budget_ms: int = 8000) -> subprocess.CompletedProcess:
    profile = tmp / f"profile-{len(list(tmp.glob('profile-*')))}"
    cmd = [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--use-gl=swiftshader", "--enable-unsafe-swiftshader",
           "--disable-background-networking", "--disable-component-update", "--disable-sync", "--no-first-run",
           "--disable-quic", "--disable-dev-shm-usage", f"--user-data-dir={profile}", f"--virtual-time-budget={budget_ms}",
           *args, page.resolve().as_uri() + fragment]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)


def read_png(path: Path) -> np.ndarray:
    """Minimal PNG decoder (8-bit RGB/RGBA, non-interlaced): (h, w, channels) uint8."""
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n", "not a PNG"
    pos, idat, hdr = 8, [], None
    while pos < len(data):
        (length,), kind = struct.unpack(">I", data[pos:pos + 4]), data[pos + 4:pos + 8]
        body = data[pos + 8:pos + 8 + length]
        if kind == b"IHDR":
            hdr = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat.append(body)
        pos += 12 + length
    w, h, depth, ctype, _, _, interlace = hdr
    assert depth == 8 and ctype in (2, 6) and interlace == 0, f"unsupported PNG {hdr}"
    bpp = 3 if ctype == 2 else 4
    raw = np.frombuffer(zlib.decompress(b"".join(idat)), dtype=np.uint8).reshape(h, 1 + w * bpp)
    out = np.zeros((h, w * bpp), dtype=np.int32)
    prev = np.zeros(w * bpp, dtype=np.int32)
    for y in range(h):
        f, line = raw[y, 0], raw[y, 1:].astype(np.int32)
        if f == 0:
            cur = line
        elif f == 1:  # Sub: cumulative sum per channel
            cur = np.cumsum(line.reshape(w, bpp), axis=0).reshape(-1) % 256
        elif f == 2:
            cur = (line + prev) % 256
        else:  # Average / Paeth: sequential along the row
            cur = line.copy()
            for x in range(w * bpp):
                left = cur[x - bpp] if x >= bpp else 0
                up = prev[x]
                if f == 3:
                    cur[x] = (cur[x] + (left + up) // 2) % 256
                else:
                    ul = prev[x - bpp] if x >= bpp else 0
                    p = left + up - ul
                    pa, pb, pc = abs(p - left), abs(p - up), abs(p - ul)
                    pred = left if pa <= pb and pa <= pc else (up if pb <= pc else ul)
                    cur[x] = (cur[x] + pred) % 256
        out[y] = cur
        prev = cur
    return out.reshape(h, w, bpp).astype(np.uint8)


class _Grab(HTMLParser):
    def __init__(self):
        super().__init__()
        self.ids: list[str] = []
        self.status: dict | None = None
        self.tags: list[tuple[str, dict]] = []

    def handle_starttag(self, tag, attrs):
        d = dict(attrs)
        self.tags.append((tag, d))
        if "data-grasp-id" in d:
            self.ids.append(d["data-grasp-id"])
        if d.get("id") == "render-status":
            self.status = d


def parse_dom(text: str) -> _Grab:
    g = _Grab()
    g.feed(text)
    return g


# ----------------------------------------------------------------------------- fixtures
@pytest.fixture(scope="module")
def bracket_plan(tmp_path_factory) -> tuple[dict, Path]:
    doc = synthetic_result(BRACKET)
    folder = tmp_path_factory.mktemp("viewer")
    p = folder / "plan.json"
    p.write_text(json.dumps(doc))
    return doc, p


@pytest.fixture(scope="module")
def bracket_page(bracket_plan, tmp_path_factory) -> Path:
    doc, p = bracket_plan
    return write_viewer(p, p.parent / "view.html")


# ----------------------------------------------------------------------------- unit tests (no browser)
def test_png_decoder_against_zlib_encoded_image(tmp_path):
    """The minimal decoder, on a PNG written here with every filter type (0-4)."""
    rng = np.random.default_rng(0)
    img = rng.integers(0, 256, size=(5, 7, 3), dtype=np.uint8)
    img[2] = img[1]  # some structure
    h, w, c = img.shape
    rows = []
    prev = np.zeros(w * c, dtype=np.int64)
    for y in range(h):
        cur = img[y].reshape(-1).astype(np.int64)
        f = y % 5
        left = np.concatenate([np.zeros(c, dtype=np.int64), cur[:-c]])
        ul = np.concatenate([np.zeros(c, dtype=np.int64), prev[:-c]])
        if f == 0:
            enc = cur
        elif f == 1:
            enc = cur - left
        elif f == 2:
            enc = cur - prev
        elif f == 3:
            enc = cur - (left + prev) // 2
        else:
            p = left + prev - ul
            pa, pb, pc = np.abs(p - left), np.abs(p - prev), np.abs(p - ul)
            enc = cur - np.where((pa <= pb) & (pa <= pc), left, np.where(pb <= pc, prev, ul))
        rows.append(bytes([f]) + (enc % 256).astype(np.uint8).tobytes())
        prev = cur

    def chunk(kind, body):
        return struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))

    png = tmp_path / "t.png"
    png.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
                    + chunk(b"IDAT", zlib.compress(b"".join(rows))) + chunk(b"IEND", b""))
    assert np.array_equal(read_png(png), img)


def test_densify_path_step_and_waypoints():
    P = np.array([[0.0, 0, 0], [0.3, 0, 0], [0.3, -0.09, 0.01], [0.3, -0.09, 0.01]])
    S, idx = densify_path(P, step=0.03)
    assert np.allclose(S[idx], P)  # every waypoint is a sample
    assert np.abs(np.diff(S, axis=0)).max() <= 0.03 + 1e-12
    assert len(S) == 1 + 10 + 3  # the repeated last waypoint adds no sample ...
    assert idx.tolist() == [0, 10, 13, 13]  # ... and maps onto the same one
    assert np.all(np.linalg.norm(np.diff(S, axis=0), axis=1) > 0)
    S2, idx2 = densify_path(np.array([[0.0], [100.0]]), step=0.03, max_samples=50)
    assert len(S2) <= 50 and np.allclose(S2[idx2], [[0.0], [100.0]])


def test_decimate_keeps_shape_and_budget():
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=5, radius=0.1)  # 20480 faces
    V, F = decimate_mesh(m.vertices, m.faces, 3000)
    assert 500 < len(F) <= 3000
    r = np.linalg.norm(V, axis=1)
    assert np.all(np.abs(r - 0.1) < 0.01)  # still a sphere of radius 0.1
    assert F.max() < len(V) and np.all(F[:, 0] != F[:, 1])


def _dec(s: str, dtype) -> np.ndarray:
    import base64

    return np.frombuffer(zlib.decompress(base64.b64decode(s)), dtype=dtype)


def test_page_data_matches_the_result(bracket_plan):
    from scipy.spatial.transform import Rotation

    doc, p = bracket_plan
    data, notes = build_data(load_result(doc), part_path=BRACKET)
    n = len(doc["grasps"])
    G = data["grasps"]
    assert G["n"] == n
    ids = _dec(G["id"], "<i4")
    assert ids.tolist() == [g["id"] for g in doc["grasps"]]
    names = [s["name"] for s in data["statuses"]]
    assert [names[k] for k in _dec(G["status"], "u1")] == [g["status"] for g in doc["grasps"]]
    assert {int(k): v for k, v in G["rank"].items()} == {g["id"]: g["rank"] for g in doc["grasps"] if g["rank"] is not None}
    # contacts in the world frame = T_world_part applied to the part-frame contacts, via the pair table
    T = np.asarray(doc["part"]["T_world_part"])
    pairs = _dec(G["pairs"], "<f4").reshape(-1, 6)
    pair = _dec(G["pair"], "<u4")
    assert len(pairs) < n  # the roll variants share their contact pair
    ref = np.array([g["contacts"] for g in doc["grasps"]]) @ T[:3, :3].T + T[:3, 3]
    assert np.allclose(pairs[pair].reshape(n, 2, 3), ref, atol=1e-6)
    assert np.allclose(_dec(G["width"], "<f4")[pair], [g["width"] for g in doc["grasps"]], atol=1e-6)
    assert np.allclose(_dec(G["opening"], "<f4")[pair], np.minimum(doc["gripper"]["max_opening"], np.array([g["width"] for g in doc["grasps"]]) + 0.01), atol=1e-6)
    # every (pair, status) has one marker
    ms, mp = _dec(G["marker_status"], "u1"), _dec(G["marker_pair"], "<u4")
    assert set(zip(ms.tolist(), mp.tolist())) == set(zip(_dec(G["status"], "u1").tolist(), pair.tolist()))
    # TCP poses: T_world_part @ T_part_tcp (quaternions quantised to 1/32767)
    Tw = T[None] @ np.array([g["T_part_tcp"] for g in doc["grasps"]])
    assert np.allclose(_dec(G["tcp_p"], "<f4").reshape(n, 3), Tw[:, :3, 3], atol=1e-6)
    q = _dec(G["tcp_q"], "<i2").reshape(n, 4) / 32767.0
    assert np.allclose(Rotation.from_quat(q).as_matrix(), Tw[:, :3, :3], atol=2e-4)
    # robot: each link mesh once, the last sample of every planned path is q_grasp (TCP = grasp TCP)
    R = data["robot"]
    planned = [g for g in doc["grasps"] if g["status"] == "planned"]
    assert set(R["paths"]) == {str(g["id"]) for g in planned} and len(planned) == 3
    assert len(R["meshes"]) == len(R["links"]) == 7
    frames = _dec(R["frames"], "<f4").reshape(-1, R["frame_size"], 7)
    for g in planned:
        P = R["paths"][str(g["id"])]
        last = frames[P["start"] + P["count"] - 1, -1]
        Tg = T @ np.asarray(g["T_part_tcp"])
        assert np.allclose(last[:3], Tg[:3, 3], atol=1e-5)
        assert np.allclose(Rotation.from_quat(last[3:]).as_matrix(), Tg[:3, :3], atol=1e-5)
        pre = frames[P["start"] + P["pregrasp"], -1]
        assert np.allclose(pre[:3], Tg[:3, 3] - 0.05 * Tg[:3, 2], atol=1e-5)


def test_malformed_grasp_is_named_small_and_unsampled(bracket_plan):
    """A malformed grasp is named by its index: in a small document (JSON Schema on every grasp) and
    in a large one where the grasp is not in the schema sample (the vectorised check)."""
    doc, _ = bracket_plan
    from grasplan.results.reader import SCHEMA_SAMPLE

    small = [dict(g) for g in doc["grasps"][:20]]
    small[7]["T_part_tcp"] = [[1, 0, 0], [0, 1, 0]]
    with pytest.raises(InputError, match=r"grasps\[7\].*T_part_tcp"):
        build_html({**doc, "grasps": small}, part_path=BRACKET)
    grasps = [dict(g) for g in doc["grasps"]]
    assert len(grasps) > SCHEMA_SAMPLE
    step = max(1, len(grasps) // SCHEMA_SAMPLE)
    k = next(i for i in range(1, len(grasps)) if i % step and grasps[i]["status"] != "planned")
    grasps[k]["width"] = "wide"
    with pytest.raises(InputError, match=rf"grasps\[{k}\] \(id {k}\): 'width' missing or malformed"):
        load_result({**doc, "grasps": grasps})


def test_malformed_grasp_is_named(bracket_plan):
    doc, _ = bracket_plan
    grasps = [dict(g) for g in doc["grasps"]]
    grasps[7]["T_part_tcp"] = [[1, 0, 0], [0, 1, 0]]
    with pytest.raises(InputError, match=r"grasps\[7\].*T_part_tcp"):
        build_html({**doc, "grasps": grasps}, part_path=BRACKET)
    with pytest.raises(InputError, match=r"grasps\[7\].*T_part_tcp"):
        load_result({**doc, "grasps": grasps})


def test_page_is_self_contained(bracket_page):
    text = bracket_page.read_text()
    g = parse_dom(text)
    # no external resource of any kind
    for tag, attrs in g.tags:
        assert tag != "link", f"<link> found: {attrs}"
        assert not (tag == "script" and "src" in attrs), f"<script src> found: {attrs}"
        for k in ("src", "href", "action", "data", "poster"):
            assert not re.match(r"\s*(https?:)?//", attrs.get(k) or ""), f"external {k} on <{tag}>: {attrs}"
    assert not re.search(r"""(import\s*\(|from\s+|fetch\s*\(|url\s*\()\s*['"]?\s*(https?:)?//""", text), "external import/fetch/url"
    assert not re.search(r"@import", text)
    # every request is refused by the page's CSP
    csp = re.search(r'<meta http-equiv="Content-Security-Policy" content="([^"]+)"', text)
    assert csp and "default-src 'none'" in csp.group(1) and "connect-src 'none'" in csp.group(1)
    assert "script-src 'unsafe-inline'" in csp.group(1) and "http" not in csp.group(1)
    # three.js and its licence are bundled
    assert "three.js authors" in text and "Permission is hereby granted" in text
    assert "OrbitControls" in text
    # the only http(s) URL anywhere is the XHTML namespace string inside three.js
    assert set(re.findall(r"https?://[^\s\"'<>)]*", text)) <= {"http://www.w3.org/1999/xhtml"}


def test_bad_inputs(tmp_path, bracket_plan):
    doc, _ = bracket_plan
    with pytest.raises(InputError, match="not a grasplan grasps or plan file: schema is 'grasplan.candidates/1'"):
        build_html({"schema": "grasplan.candidates/1", "part": {}, "grasps": []})
    bad = {**doc, "part": {**doc["part"], "path": str(tmp_path / "missing.stl")}}
    with pytest.raises(InputError, match="--part"):
        build_html(bad)
    with pytest.raises(InputError, match="no such file"):
        build_html(tmp_path / "nothing.json")
    out = tmp_path / "v.html"
    with pytest.raises(InputError):
        write_viewer(bad, out)
    assert not out.exists()  # nothing written


def test_relative_part_path_resolved_from_the_result_folder(tmp_path, monkeypatch):
    doc = synthetic_result(BRACKET, plan=False)
    shutil.copy(BRACKET, tmp_path / "bracket.stl")
    doc["part"]["path"] = "bracket.stl"
    (tmp_path / "res").mkdir()
    res = tmp_path / "res" / "grasps.json"
    shutil.copy(BRACKET, tmp_path / "res" / "bracket.stl")
    res.write_text(json.dumps(doc))
    monkeypatch.chdir(tmp_path / "res")
    assert "grasplan-data" in build_html(res)
    monkeypatch.chdir(ROOT)  # not in the cwd: found next to the result
    assert not (ROOT / "bracket.stl").exists()
    loaded = load_result(res)
    data, _ = build_data(loaded)
    assert data["part"]["nv"] == len(load_part(BRACKET).mesh.vertices)
    (tmp_path / "res" / "bracket.stl").unlink()   # and only there: now it is missing
    with pytest.raises(InputError, match="--part"):
        build_data(load_result(res))
    # a part whose sha256 differs is an error (issue 14) unless allowed explicitly
    doc["part"]["sha256"] = "0" * 64
    with pytest.raises(InputError, match=r"sha256 .* differs from the result's part.*--allow-other-part"):
        build_html(doc, part_path=BRACKET)
    assert "grasplan-data" in build_html(doc, part_path=BRACKET, allow_other_part=True)


def test_cli_view(tmp_path, bracket_plan):
    from click.testing import CliRunner

    from grasplan.cli import main

    _, p = bracket_plan
    out = tmp_path / "v.html"
    r = CliRunner().invoke(main, ["view", str(p), "-o", str(out), "--part", str(BRACKET)])
    assert r.exit_code == 0, r.output
    assert out.exists() and str(out) in r.stdout
    r = CliRunner().invoke(main, ["view", str(tmp_path / "none.json"), "-o", str(tmp_path / "x.html")])
    assert r.exit_code == 3 and not (tmp_path / "x.html").exists()
    # another part than the result's: exit 3 naming the fix, unless --allow-other-part
    other = ROOT / "examples" / "parts" / "gear.stl"
    out2 = tmp_path / "other.html"
    r = CliRunner().invoke(main, ["view", str(p), "-o", str(out2), "--part", str(other)])
    assert r.exit_code == 3 and "sha256" in r.output and not out2.exists()
    r = CliRunner().invoke(main, ["view", str(p), "-o", str(out2), "--part", str(other), "--allow-other-part"])
    assert r.exit_code == 0 and out2.exists(), r.output


@pytest.mark.paper
@pytest.mark.slow
def test_size_tless22_with_ur5(paper, tmp_path):
    path = paper("TLess22.stl")
    doc = synthetic_result(path, units="auto", n_planned=20)
    text = build_html(doc)
    size = len(text.encode())
    assert load_part(path).triangles > 20_000
    assert size < 15e6, f"{size / 1e6:.1f} MB"


# ----------------------------------------------------------------------------- in the browser
def _check_rendered(dom: str, doc: dict) -> _Grab:
    g = parse_dom(dom)
    assert g.status is not None, "no #render-status in the DOM"
    assert g.status.get("data-ok") == "1", f"page did not render: {g.status.get('data-error')}"
    assert int(g.status["data-triangles"]) >= doc["part"]["triangles"] // 2
    planned = {str(x["id"]) for x in doc["grasps"] if x["status"] in ("planned", "ok")}
    assert planned <= set(g.ids), f"missing from the list: {sorted(planned - set(g.ids))[:10]}"
    assert len(g.ids) == len(set(g.ids))
    return g


def _canvas(png: Path) -> np.ndarray:
    """The 3D view's pixels of a 1280x800 screenshot, (h, w, 3) uint8 (rows CANVAS_Y0:CANVAS_Y1)."""
    return read_png(png)[CANVAS_Y0:CANVAS_Y1, CANVAS_X0 + 2:, :3]


def _canvas_stats(img: np.ndarray) -> tuple[int, float]:
    """(distinct colours, pixel standard deviation): a blank canvas has ~1 colour and std ~0."""
    return len(np.unique(img.reshape(-1, 3), axis=0)), float(img.astype(float).std())


@pytest.mark.browser
@pytest.mark.slow
@needs_chromium
def test_browser_renders_synthetic_plan(bracket_plan, bracket_page, tmp_path):
    doc, _ = bracket_plan
    r = run_chromium(bracket_page, tmp_path, "--dump-dom")
    assert r.returncode == 0, r.stderr[-2000:]
    g = _check_rendered(r.stdout, doc)
    best = min((x for x in doc["grasps"] if x["status"] == "planned"), key=lambda x: x["rank"])
    assert g.status["data-selected"] == str(best["id"])  # the best planned grasp is selected
    png = tmp_path / "shot.png"
    r = run_chromium(bracket_page, tmp_path, f"--screenshot={png}", "--window-size=1280,800")
    assert png.exists(), r.stderr[-2000:]
    shot = read_png(png)[:, CANVAS_X0 + 2:, :3]
    colours, std = _canvas_stats(shot[CANVAS_Y0:CANVAS_Y1])
    assert colours > 200 and std > 10, (colours, std)
    img = shot.reshape(-1, 3).astype(int)
    # the robot (orange links) and the planned contacts (green) are visible
    assert np.sum((img[:, 0] > 200) & (img[:, 1] > 120) & (img[:, 1] < 190) & (img[:, 2] < 110)) > 500, "no robot"
    green = np.array([int(STATUS_COLORS["planned"][k:k + 2], 16) for k in (1, 3, 5)])
    assert np.sum(np.abs(img - green).sum(1) < 40) > 5, "no planned contact drawn"


@pytest.mark.browser
@needs_chromium
def test_browser_plays_a_path(bracket_plan, bracket_page, tmp_path):
    """#grasp=ID&play selects a planned grasp and plays its path to the end (q_grasp)."""
    doc, _ = bracket_plan
    data, _ = build_data(load_result(doc), part_path=BRACKET)
    worst = max((x for x in doc["grasps"] if x["status"] == "planned"), key=lambda x: x["rank"])
    # the path takes count / 60 s to play; the page's start (inflating the arrays) also uses virtual time
    r = run_chromium(bracket_page, tmp_path, "--dump-dom", fragment=f"#grasp={worst['id']}&play", budget_ms=15000)
    st = _check_rendered(r.stdout, doc).status
    assert st["data-selected"] == str(worst["id"])
    assert st.get("data-played") == str(data["robot"]["paths"][str(worst["id"])]["count"])


@pytest.mark.browser
@pytest.mark.slow
@needs_chromium
def test_browser_blank_page_detected(tmp_path):
    """The canvas check can fail: a page whose script breaks leaves a blank canvas and no data-ok."""
    doc = synthetic_result(BRACKET, plan=False)
    text = build_html(doc, part_path=BRACKET).replace("new THREE.WebGLRenderer", "new THREE.NoSuchRenderer")
    page = tmp_path / "broken.html"
    page.write_text(text)
    png = tmp_path / "shot.png"
    run_chromium(page, tmp_path, f"--screenshot={png}", "--window-size=1280,800")
    colours, std = _canvas_stats(_canvas(png))
    assert colours < 50 or std < 10
    r = run_chromium(page, tmp_path, "--dump-dom")
    assert parse_dom(r.stdout).status.get("data-ok") == "0"


@pytest.mark.browser
@pytest.mark.slow
@needs_chromium
def test_browser_no_network(bracket_plan, bracket_page, tmp_path):
    """Every host unresolvable and a dead proxy: the page still renders and the browser logs no
    refused request; a request injected on purpose is refused by the page's CSP and logged, so the
    log would have shown one of ours."""
    doc, _ = bracket_plan
    offline = ("--host-resolver-rules=MAP * ~NOTFOUND", "--proxy-server=http://127.0.0.1:9",
               "--enable-logging=stderr", "--v=0")
    r = run_chromium(bracket_page, tmp_path, "--dump-dom", *offline)
    _check_rendered(r.stdout, doc)
    assert "Content Security Policy" not in r.stderr and "Refused to" not in r.stderr, r.stderr[-2000:]
    assert "net::ERR" not in r.stderr, r.stderr[-2000:]
    text = bracket_page.read_text().replace(
        "</body>", "<script>fetch('http://example.invalid/x').then(()=>document.body.dataset.net='ok',"
                   "()=>document.body.dataset.net='blocked')</script></body>")
    probe = tmp_path / "probe.html"
    probe.write_text(text)
    r = run_chromium(probe, tmp_path, "--dump-dom", *offline)
    body = [a for t, a in parse_dom(r.stdout).tags if t == "body"][0]
    assert body.get("data-net") == "blocked"
    assert "Content Security Policy" in r.stderr, r.stderr[-2000:]


@pytest.mark.browser
@needs_chromium
def test_browser_many_grasps_list_is_chunked(tmp_path):
    """Thousands of grasps: every planned/ok one is listed, the others in chunks with 'show more'."""
    doc = synthetic_result(BRACKET, plan=False)
    base = doc["grasps"]
    grasps = []
    rng = np.random.default_rng(1)
    for k in range(4000):
        g = dict(base[k % len(base)])
        g["id"] = k
        g["status"] = "ok" if k % 9 == 0 else str(rng.choice(["collision_part", "collision_table"]))
        grasps.append(g)
    doc["grasps"] = grasps
    page = tmp_path / "many.html"
    write_viewer(doc, page, part_path=BRACKET)
    r = run_chromium(page, tmp_path, "--dump-dom")
    g = _check_rendered(r.stdout, doc)
    from grasplan.viewer.page import LIST_CHUNK

    n_ok = sum(1 for x in grasps if x["status"] == "ok")
    assert len(g.ids) == n_ok + 2 * LIST_CHUNK  # ok: all of them; the others: one chunk each


@pytest.mark.browser
@pytest.mark.paper
@pytest.mark.slow
@needs_chromium
def test_browser_tless20_plan(paper, tmp_path):
    """The issue's acceptance check: a real `grasplan plan` of TLess20 with the UR5, rendered."""
    path = paper("TLess20.stl")
    from grasplan.config.params import PlanParams
    from grasplan.motion.planning import plan

    result = plan(load_part(path), robot="ur5", planning=PlanParams(top=3, seed=0, budget_s=30.0))
    doc = result.to_json()
    assert any(g["status"] == "planned" for g in doc["grasps"])
    page = write_viewer(result, tmp_path / "tless20.html", part_path=path)
    assert page.stat().st_size < 15e6  # ~1.8e5 grasps: about 3 MB
    r = run_chromium(page, tmp_path, "--dump-dom")
    _check_rendered(r.stdout, doc)
    png = tmp_path / "tless20.png"
    run_chromium(page, tmp_path, f"--screenshot={png}", "--window-size=1280,800")
    colours, std = _canvas_stats(_canvas(png))
    assert colours > 200 and std > 10, (colours, std)


# ----------------------------------------------------------------------------- pick-and-place, obstacles
def sequence_result_with_obstacles() -> dict:
    """The bracket plan above with its planned grasps extended to pick-and-place sequences (lift,
    transfer, descend, release, retreat; tests/test_export_sequence.py) and a cell with one
    obstacle of each kind."""
    from test_export import mini_ur5
    from test_export_sequence import add_sequence

    from grasplan.gripper.load import load_gripper

    doc = synthetic_result(BRACKET, n_planned=2)
    ur5, gr = mini_ur5(), load_gripper("schunk_egp_c_40")
    T = np.asarray(doc["part"]["T_world_part"])
    doc["grasps"] = [add_sequence(ur5, g, T, float(gr.pregrasp_opening(g["width"]))) if g["status"] == "planned" else g
                     for g in doc["grasps"]]

    def at(x, y, z):
        M = np.eye(4)
        M[:3, 3] = (x, y, z)
        return M.tolist()

    doc["cell"]["obstacles"] = [
        {"name": "wall", "box": {"size": [0.02, 0.4, 0.3]}, "T_world_obstacle": at(0.6, 0.0, 0.15)},
        {"name": "post", "cylinder": {"radius": 0.02, "length": 0.3}, "T_world_obstacle": at(0.4, 0.2, 0.15)},
        {"name": "ball", "sphere": {"radius": 0.03}, "T_world_obstacle": at(0.3, 0.25, 0.2)},
        {"name": "tet", "mesh": {"vertices": [[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0], [0, 0, 0.1]],
                                 "faces": [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]}, "T_world_obstacle": at(0.3, -0.35, 0)},
    ]
    return doc


@pytest.fixture(scope="module")
def sequence_page(tmp_path_factory) -> tuple[dict, Path, dict]:
    doc = sequence_result_with_obstacles()
    folder = tmp_path_factory.mktemp("viewer-seq")
    p = folder / "plan.json"
    p.write_text(json.dumps(doc))
    data, _ = build_data(load_result(p), part_path=BRACKET)
    return doc, write_viewer(p, folder / "view.html", part_path=BRACKET), data


def test_page_data_has_obstacles_and_sequence(sequence_page):
    doc, _, data = sequence_page
    obs = data["cell"]["obstacles"]
    assert [(o["name"], o["kind"]) for o in obs] == [("wall", "box"), ("post", "cylinder"), ("ball", "sphere"),
                                                     ("tet", "mesh")]
    for o, src in zip(obs, doc["cell"]["obstacles"]):
        np.testing.assert_allclose(np.reshape(o["T"], (4, 4)), src["T_world_obstacle"])
    assert obs[0]["box"] == [0.02, 0.4, 0.3] and obs[1]["cylinder"] == [0.02, 0.3] and obs[3]["mesh"]["nf"] == 4
    for g in (x for x in doc["grasps"] if x["status"] == "planned"):
        P = data["robot"]["paths"][str(g["id"])]
        assert [s["label"] for s in P["segments"]] == [s["label"] for s in g["segments"]]
        starts = [s["start"] for s in P["segments"]]
        assert starts[0] == 0 and P["segments"][-1]["end"] == P["count"] - 1
        assert all(a["end"] == b["start"] for a, b in zip(P["segments"], P["segments"][1:]))
        ev = {e["action"]: e for e in P["events"]}
        seg = {s["label"]: s for s in P["segments"]}
        assert ev["close"]["sample"] == seg["approach"]["end"] and ev["open"]["sample"] == seg["descend"]["end"]
        assert P["attached"] == [ev["close"]["sample"], ev["open"]["sample"]]
        np.testing.assert_allclose(np.reshape(P["T_tcp_part"], (4, 4)), g["T_tcp_part"])
        np.testing.assert_allclose(np.reshape(P["T_world_part_place"], (4, 4)), g["T_world_part_place"])


@pytest.mark.browser
@needs_chromium
def test_browser_sequence_obstacles_and_part_in_the_jaws(sequence_page, tmp_path):
    """The page draws the 4 obstacles, labels the segments on the timeline in order, and moves the
    part: attached in the transfer, at the place after the release; no script error."""
    doc, page, data = sequence_page
    best = min((x for x in doc["grasps"] if x["status"] == "planned"), key=lambda x: x["rank"])
    P = data["robot"]["paths"][str(best["id"])]
    seg = {s["label"]: s for s in P["segments"]}
    for sample, phase, part in ((0, "transit", "static"),
                                ((seg["transfer"]["start"] + seg["transfer"]["end"]) // 2, "transfer", "attached"),
                                (P["count"] - 1, "retreat", "placed")):
        r = run_chromium(page, tmp_path, "--dump-dom", "--enable-logging=stderr", "--v=0",
                         fragment=f"#grasp={best['id']}&sample={sample}")
        g = _check_rendered(r.stdout, doc)
        st = g.status
        assert "data-error" not in st, st.get("data-error")
        assert "Uncaught" not in r.stderr, r.stderr[-2000:]
        assert st["data-obstacles"] == "4"
        assert st["data-segments"] == ",".join(s["label"] for s in best["segments"])
        labels = [a["data-segment"] for t, a in g.tags if "data-segment" in a]
        assert labels == [s["label"] for s in best["segments"]]
        assert [a["data-event"] for t, a in g.tags if "data-event" in a] == ["close", "open"]
        assert (st["data-phase"], st["data-part"]) == (phase, part)


@pytest.mark.browser
@needs_chromium
def test_browser_shows_quality_and_sim(tmp_path):
    """quality and sim of a grasp (issue 11 keys) appear in the grasp panel when the plan has them."""
    doc = synthetic_result(BRACKET, n_planned=2)
    best = min((x for x in doc["grasps"] if x["status"] == "planned"), key=lambda x: x["rank"])
    for g in doc["grasps"]:
        if g["status"] not in ("collision_part", "collision_table"):
            g["quality"] = {"score": g["score"], "gravity_margin": 1.75, "epsilon": 0.0123,
                            "contact": [{"area_m2": 2.5e-5, "type": "surface"}, {"area_m2": 1e-6, "type": "line"}]}
    best["sim"] = {"success": True, "slip_m": 0.0004, "turn_deg": 1.5}
    res = load_result(doc)
    if getattr(res.grasps, "gravity_margin", None) is None:
        pytest.skip("this grasplan's result loader does not read grasp quality (issue 11) yet")
    page = write_viewer(doc, tmp_path / "q.html", part_path=BRACKET)
    r = run_chromium(page, tmp_path, "--dump-dom", fragment=f"#grasp={best['id']}")
    _check_rendered(r.stdout, doc)
    panel = re.search(r'<div id="selected">(.*?)</div>', r.stdout, re.S).group(1)
    assert "gravity margin 1.75" in panel and "epsilon 0.0123" in panel, panel
    assert "surface 25.0 mm" in panel and "line 1.0 mm" in panel, panel
    assert "sim: held" in panel and "slip 0.4 mm" in panel and "turn 1.5" in panel, panel


def test_every_status_has_its_own_colour():
    """Each grasp status the pipeline can write is drawn in a colour of its own."""
    from grasplan.status import GRASP_STATUSES, PLAN_STATUSES

    statuses = set(PLAN_STATUSES) | set(GRASP_STATUSES)
    assert statuses <= set(STATUS_COLORS), sorted(statuses - set(STATUS_COLORS))
    colours = [STATUS_COLORS[s] for s in statuses]
    assert len(set(colours)) == len(colours) and OTHER_COLOR not in colours
