"""Inputs shared by tests/test_inputs_shift.py and tests/test_fuzz_formats.py: one plan and one
picks file (each built once per test session), small mesh files and robot descriptions whose
meshes exceed the limits (a binary STL header claiming millions of triangles in a sparse file of
the matching size: refused from the header, never read)."""
from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
BOX = ROOT / "examples" / "parts" / "box.stl"
BRACKET = ROOT / "examples" / "parts" / "bracket.stl"
#: every export format, with the file name each is written to (KRL/RAPID: a valid program name)
FORMATS = {"csv": "out.csv", "joint-trajectory": "out.json", "krl": "pick_out.src", "moveit-grasp": "out.yaml",
           "path-csv": "out_path.csv", "rapid": "pick_out.mod", "urscript": "out.script"}
_BUILT: dict[str, object] = {}


def _once(fn):
    """``fn(factory)`` computed once per test session (pytest's ``tmp_path_factory``)."""
    def get(factory):
        if fn.__name__ not in _BUILT:
            _BUILT[fn.__name__] = fn(factory)
        return _BUILT[fn.__name__]
    get.__doc__ = fn.__doc__
    return get


@_once
def plan_result(factory):
    """A UR5 plan of examples/parts/box.stl with at least one planned grasp (once per session)."""
    import grasplan

    res = grasplan.plan(grasplan.load_part(BOX), "ur5", grasps=grasplan.GraspParams(roll_step_deg=90),
                        planning=grasplan.PlanParams(top=2, seed=0))
    assert res.planned_ids(), res.counts()
    return res


@_once
def plan_file(factory) -> Path:
    """:func:`plan_result` written to a file (next to a copy of its part)."""
    folder = factory.mktemp("shift_plan")
    path = folder / "plan.json"
    plan_result(factory).write(path)
    return path


@_once
def picks_file(factory) -> Path:
    """A ``grasplan.picks/1`` file: one bracket picked from the bin by the UR5 (its grasp database
    cached in a session folder, not the user's cache)."""
    from grasplan.cell.model import load_cell
    from grasplan.part.mesh import load_part
    from grasplan.pick import Picker, PickParams
    from grasplan.piles.scene_file import Instance, Scene
    from grasplan.cell.resting import stable_pose

    folder = factory.mktemp("shift_picks")
    old = os.environ.get("GRASPLAN_CACHE_DIR")
    os.environ["GRASPLAN_CACHE_DIR"] = str(folder / "cache")
    try:
        part = load_part(BRACKET)
        rest = stable_pose(part.mesh, load_cell("bin"))
        picker = Picker("ur5", params=PickParams(grasps_per_instance=8))
        picker.add_part("bracket", part)
        res = picker.plan(Scene(instances=(Instance("a", "bracket", rest),), cell="bin"))
    finally:
        if old is None:
            os.environ.pop("GRASPLAN_CACHE_DIR", None)
        else:
            os.environ["GRASPLAN_CACHE_DIR"] = old
    assert res.picks, res.instances
    path = folder / "picks.json"
    res.write(path)
    return path


def document(path: Path) -> dict:
    return json.loads(path.read_text())


# -- meshes ----------------------------------------------------------------------------------------

def tetra() -> tuple[np.ndarray, np.ndarray]:
    """A closed tetrahedron, 20 mm edges along the axes (file units mm), outward faces."""
    v = np.array([[0, 0, 0], [20, 0, 0], [0, 20, 0], [0, 0, 20.0]])
    f = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    return v, f


def huge_stl(path: Path, triangles: int) -> Path:
    """A binary STL whose header declares ``triangles`` and whose size matches (a sparse file: the
    records are zeros and take no disk space)."""
    with open(path, "wb") as fh:
        fh.write(b"\0" * 80 + np.uint32(triangles).tobytes())
        fh.truncate(84 + 50 * triangles)
    return path


def robot_yaml(folder: Path, meshes: dict[str, str], *, visual: dict[str, str] | None = None,
               name: str = "meshbot") -> Path:
    """A two-joint robot (a URDF and its YAML in ``folder``) whose links' collision meshes are
    ``meshes`` (link -> mesh file name as written in the URDF) and visual meshes ``visual``."""
    links = sorted(set(meshes) | set(visual or {}) | {"base", "l1", "l2"})
    body = []
    for ln in links:
        parts = []
        if ln in meshes:
            parts.append(f'<collision><geometry><mesh filename="{meshes[ln]}"/></geometry></collision>')
        if visual and ln in visual:
            parts.append(f'<visual><geometry><mesh filename="{visual[ln]}"/></geometry></visual>')
        body.append(f'<link name="{ln}">{"".join(parts)}</link>')
    chain = [("base", "l1"), ("l1", "l2")] + [("l2", ln) for ln in links if ln not in ("base", "l1", "l2")]
    for k, (a, b) in enumerate(chain):
        kind = "revolute" if k < 2 else "fixed"
        limit = '<limit lower="-3" upper="3" effort="10" velocity="1"/><axis xyz="0 0 1"/>' if k < 2 else ""
        body.append(f'<joint name="j{k}" type="{kind}"><parent link="{a}"/><child link="{b}"/>'
                    f'<origin xyz="0 0 0.1"/>{limit}</joint>')
    (folder / f"{name}.urdf").write_text(f'<robot name="{name}">' + "".join(body) + "</robot>")
    path = folder / f"{name}.yaml"
    path.write_text(yaml.safe_dump({"name": name, "urdf": f"{name}.urdf", "tool_frame": "l2", "q_home": [0, 0]}))
    return path
