"""Hostile piles for ``grasplan pick`` / ``grasplan.Picker``: one part reported several
times in one place (2 to 50 copies, also among other instances, also turned onto itself by a
symmetry), nearly coincident instances within and beyond ``--overlap-tol``, jittered piles, and
JSON scene files naming a key twice at every depth.

Every case ends one of two ways: refused as bad input (``InputError``, exit 3) with a message
naming both instance ids (or the file and the duplicated key), or planned (exit 0 or 4) with the
plan stopping within its ``--budget``; never a traceback, never a hang. Whether a pair counts as
coincident is decided here independently of grasplan (scipy's directed Hausdorff distance of the
two placed hulls' vertices, at most ``--overlap-tol``).

Deterministic (seeded). The default run takes a representative subset (library calls on one warm
picker, and a few through the command line in-process); ``GRASPLAN_FUZZ_FULL=1`` runs every case,
also on the paper part TLess20 when ../shared/parts/paper has it (docs/fuzz.md).
"""
from __future__ import annotations

import json
import os
import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from scipy.spatial.distance import directed_hausdorff

from grasplan.cell.model import load_cell
from grasplan.cli import main
from grasplan.errors import InputError
from grasplan.part.mesh import load_part
from grasplan.geometry.meshdata import convex_hull
from grasplan.pick import Picker, PickParams
from grasplan.piles.scene_file import load_scene, scene_from_dict
from grasplan.cell.resting import stable_pose
from grasplan.geometry.transforms import rpy_matrix

FULL = os.environ.get("GRASPLAN_FUZZ_FULL") == "1"
ROOT = Path(__file__).resolve().parents[1]
PARTS = ROOT / "examples" / "parts"
PAPER = Path(os.environ.get("GRASPLAN_PAPER_PARTS", ROOT.parent / "shared" / "parts" / "paper"))
TOL = 0.002  # --overlap-tol's default
BUDGET_S = 10.0
LEAKS = re.compile(r"Traceback|internal error|KeyError|IndexError|ValueError|TypeError|AttributeError|QhullError")


@pytest.fixture(scope="module")
def world():
    """A warm picker knowing the bracket and the box (and TLess20 in the full run), their resting poses."""
    pk = Picker("ur5", cell="bin", params=PickParams(budget_s=BUDGET_S, grasps_per_instance=4))
    rest = {}
    names = {"bracket": PARTS / "bracket.stl", "box": PARTS / "box.stl"}
    if FULL and (PAPER / "TLess20.stl").exists():
        names["TLess20"] = PAPER / "TLess20.stl"
    cell = load_cell("bin")
    for name, path in names.items():
        part = load_part(path)
        pk.add_part(name, part)
        rest[name] = stable_pose(part.mesh, cell)
    return pk, rest, names


def moved(T, dx=0.0, dy=0.0, dz=0.0, turn_deg=(0.0, 0.0, 0.0)):
    """``T`` moved by (dx, dy, dz) in the world and turned about its own origin by rpy ``turn_deg``."""
    out = np.array(T, dtype=np.float64)
    out[:3, :3] = out[:3, :3] @ rpy_matrix(*np.radians(turn_deg))
    out[:3, 3] += [dx, dy, dz]
    return out


def coincident(mesh, Ta, Tb) -> bool:
    """The rule, computed independently: the symmetric Hausdorff distance of the two placed hulls'
    vertex sets at most TOL."""
    h = np.asarray(convex_hull(np.asarray(mesh.vertices)).vertices)
    a, b = h @ Ta[:3, :3].T + Ta[:3, 3], h @ Tb[:3, :3].T + Tb[:3, 3]
    return max(directed_hausdorff(a, b)[0], directed_hausdorff(b, a)[0]) <= TOL


def row_poses(T, n, pitch=0.06):
    return [moved(T, pitch * (k - (n - 1) / 2)) for k in range(n)]


# -- the cases: (id, part, [(instance id, pose)], refused pair or None) ---------------------------------
def _cases():
    out = []
    counts = range(2, 51) if FULL else (2, 3, 5, 17, 50)
    for n in counts:  # n copies in one place
        out.append((f"copies{n}", "bracket", lambda T, n=n: [(f"d{k}", T) for k in range(n)], ("d0", "d1")))
    for n in ((2, 5, 20) if FULL else (2,)):  # a copy of one instance of a row, listed last
        out.append((f"row_copy{n}", "bracket",
                    lambda T, n=n: [(f"r{k}", P) for k, P in enumerate(row_poses(T, 3))]
                    + [(f"again{k}", row_poses(T, 3)[1]) for k in range(n - 1)], ("r1", "again0")))
    offsets = [(0.0005, 0, 0, (0, 0, 0)), (0.0015, 0, 0, (0, 0, 0)), (0, 0.001, 0.0005, (0, 0, 1.0)),
               (0, 0, 0, (0.5, 0.5, 0)), (0.004, 0, 0, (0, 0, 0)), (0.0025, 0.0025, 0, (0, 0, 0)),
               (0, 0, 0, (0, 0, 12.0)), (0.01, 0, 0, (0, 0, 0))]
    if FULL:
        rng = np.random.default_rng(37)
        # raised by up to 4 mm: a turn of up to 5 deg does not sink the 40 mm part into the floor
        offsets += [(*rng.uniform(-0.005, 0.005, 2), float(rng.uniform(0.002, 0.004)), tuple(rng.uniform(-5, 5, 3)))
                    for _ in range(24)]
        offsets += [(*rng.uniform(-0.001, 0.001, 2), float(rng.uniform(0.0, 0.001)), tuple(rng.uniform(-0.5, 0.5, 3)))
                    for _ in range(8)]  # within the tolerance
    for k, (dx, dy, dz, turn) in enumerate(offsets):  # nearly coincident: refused within TOL, else planned
        out.append((f"near{k}", "bracket", lambda T, o=(dx, dy, dz, turn): [("a", T), ("b", moved(T, *o[:3], o[3]))],
                    "by_rule"))
    # the box turned half a turn about its vertical axis onto itself (a symmetry: another pose, the same solid)
    out.append(("box_symmetric", "box", lambda T: [("p", T), ("q", moved(T, turn_deg=(0, 0, 180)))], "by_rule"))
    for seed in (range(8) if FULL else (0, 1)):  # a jittered row: never refused
        out.append((f"jitter{seed}", "bracket", lambda T, s=seed: _jittered(T, s), None))
    if FULL:
        out.append(("tless_copies5", "TLess20", lambda T: [(f"t{k}", T) for k in range(5)], ("t0", "t1")))
        out.append(("tless_near_out", "TLess20", lambda T: [("a", T), ("b", moved(T, 0.003))], "by_rule"))
    return out


def _jittered(T, seed):
    rng = np.random.default_rng(seed)
    return [(f"j{k}", moved(P, *rng.uniform(-0.001, 0.001, 2), 0.0, (0, 0, float(rng.uniform(-1, 1)))))
            for k, P in enumerate(row_poses(T, 4))]


CASES = _cases()


@pytest.mark.parametrize("case", CASES, ids=[c[0] for c in CASES])
def test_pile_case(world, case):
    picker, rest, _ = world
    name, part, make, refused = case
    if part not in rest:
        pytest.skip(f"{part} not available (the full run uses ../shared/parts/paper/TLess20.stl)")
    insts = make(rest[part])
    if refused == "by_rule":
        refused = ("a", "b") if insts[0][0] == "a" else ("p", "q")
        if not coincident(picker._parts[part].mesh, insts[0][1], insts[1][1]):
            refused = None
    doc = {"schema": "grasplan.scene/1", "cell": "bin",
           "instances": [{"id": i, "part": part, "T": np.asarray(T).tolist()} for i, T in insts]}
    sc = scene_from_dict(doc)
    if refused:
        with pytest.raises(InputError) as exc:
            picker.plan(sc)
        msg = str(exc.value)
        assert f"'{refused[0]}'" in msg and f"'{refused[1]}'" in msg and "same place" in msg, msg
        return
    res = picker.plan(sc)  # any exception fails the case
    assert len(res.instances) == len(insts)
    assert {r.status for r in res.instances} <= {"picked", "blocked", "cloud", "bin", "ik_collision",
                                                 "lift_collision", "unreachable", "no_path", "place", "no_grasp",
                                                 "not_tried"}
    # the plan kept its budget (generously: the clock of a busy machine)
    assert res.timing_s["total"] <= 2.0 * BUDGET_S, res.timing_s


# -- duplicate keys in JSON scenes ----------------------------------------------------------------------
_T = "[[1,0,0,0.4],[0,1,0,0],[0,0,1,0.02],[0,0,0,1]]"
DUP_KEYS = [
    ("top", "schema", '{"schema": "grasplan.scene/1", "schema": "grasplan.scene/1", "instances": '
                      '[{"id": "a", "part": "p", "T": ' + _T + '}]}'),
    ("instances", "instances", '{"schema": "grasplan.scene/1", "instances": [], "instances": '
                               '[{"id": "a", "part": "p", "T": ' + _T + '}]}'),
    ("parts", "p", '{"schema": "grasplan.scene/1", "parts": {"p": {}, "p": {"units": "mm"}}, "instances": '
                   '[{"id": "a", "part": "p", "T": ' + _T + '}]}'),
    ("part_field", "units", '{"schema": "grasplan.scene/1", "parts": {"p": {"units": "m", "units": "mm"}}, '
                            '"instances": [{"id": "a", "part": "p", "T": ' + _T + '}]}'),
    ("instance_T", "T", '{"schema": "grasplan.scene/1", "instances": [{"id": "a", "part": "p", "T": ' + _T
                        + ', "T": ' + _T + '}]}'),
    ("instance_id", "id", '{"schema": "grasplan.scene/1", "instances": [{"id": "a", "id": "b", "part": "p", "T": '
                          + _T + '}]}'),
    ("pose_xyz", "xyz", '{"schema": "grasplan.scene/1", "instances": [{"id": "a", "part": "p", "T": '
                        '{"xyz": [0.4, 0, 0.02], "xyz": [0.5, 0, 0.02], "rpy_deg": [0, 0, 0]}}]}'),
    ("cloud", "resolution", '{"schema": "grasplan.scene/1", "cloud": {"path": "c.npy", "resolution": 0.005, '
                            '"resolution": 0.01}, "instances": [{"id": "a", "part": "p", "T": ' + _T + '}]}'),
]


@pytest.mark.parametrize("case", DUP_KEYS, ids=[f"dupkey_{c[0]}" for c in DUP_KEYS])
def test_json_scene_naming_a_key_twice_is_refused(tmp_path, case):
    _, key, text = case
    path = tmp_path / "scene.json"
    path.write_text(text)
    with pytest.raises(InputError) as exc:
        load_scene(path)
    msg = str(exc.value)
    assert str(path) in msg and f'duplicate key "{key}"' in msg, msg


# -- through the command line ---------------------------------------------------------------------------
def _cli(tmp_path, doc_or_text, *extra):
    path = tmp_path / "scene.json"
    path.write_text(doc_or_text if isinstance(doc_or_text, str) else json.dumps(doc_or_text))
    out = tmp_path / "picks.json"
    r = CliRunner().invoke(main, ["pick", str(path), "-o", str(out), *extra])
    text = r.output + (r.stderr if r.stderr_bytes is not None else "")
    assert r.exit_code in (0, 3, 4), (r.exit_code, text[-800:])
    assert not LEAKS.search(text), text[-800:]
    if r.exit_code == 3:
        assert not out.exists() and not list(tmp_path.glob("*.tmp*"))
    return r.exit_code, text


CLI_CASES = ["copies50", "dupkey", "near_out"] + (["copies2_budget", "jitter"] if FULL else [])


@pytest.mark.parametrize("kind", CLI_CASES)
def test_pick_command_line(tmp_path, world, kind):
    _, rest, names = world
    T = rest["bracket"]

    def doc(insts):
        return {"schema": "grasplan.scene/1", "cell": "bin", "parts": {"bracket": {"mesh": str(names["bracket"])}},
                "instances": [{"id": i, "part": "bracket", "T": np.asarray(P).tolist()} for i, P in insts]}

    if kind in ("copies50", "copies2_budget"):
        n = 50 if kind == "copies50" else 2
        code, text = _cli(tmp_path, doc([(f"c{k}", T) for k in range(n)]), "--budget", "2")
        assert code == 3 and "'c0'" in text and "'c1'" in text
    elif kind == "dupkey":
        text_in = json.dumps(doc([("a", T)])).replace('"part": "bracket"', '"part": "bracket", "part": "bracket"')
        code, text = _cli(tmp_path, text_in)
        assert code == 3 and 'duplicate key "part"' in text and "scene.json" in text
    else:
        insts = [("a", T), ("b", moved(T, 0.004))] if kind == "near_out" else _jittered(T, 3)
        code, text = _cli(tmp_path, doc(insts), "--budget", "5")
        assert code in (0, 4)
