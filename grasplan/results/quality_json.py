"""The JSON of a grasp table's quality and simulation columns and of the part's mass record: the
``quality`` and ``sim`` fields of each grasp (:func:`quality_field`, :func:`sim_field`, one
definition for the dicts and the streamed text of :mod:`grasplan.results.writer`), the ``part``
mass record (``mass_kg``, ``com``, ...), and the parsers that read them back, naming the grasp at
fault."""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from ..errors import InputError
from .json_columns import Bools, Field, Items, Names, Numbers, Record

if TYPE_CHECKING:
    from .grasp_table import GraspTable

#: contact type codes (``Quality.contact_type``, ``GraspTable.contact_type``): the JSON names they index
CONTACT_TYPES = ("point", "line", "surface")
#: decimals of ``hold_force_N`` in files (0.01 N)
HOLD_FORCE_DECIMALS = 2


def hold_force(gravity_margin: np.ndarray, grip_force: float) -> np.ndarray:
    """(M,) the grip force (N, both jaws) at which each grasp is predicted to just hold under the
    shared lift-and-shake load: ``grip_force / gravity_margin``, exact because the margin is
    homogeneous in the normal force (:func:`grasplan.grasps.wrench.gravity_margin`); NaN where the
    margin is not positive (no force holds it) or unknown."""
    gm = np.asarray(gravity_margin, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(np.isfinite(gm) & (gm > 0), float(grip_force) / np.where(gm > 0, gm, 1.0), np.nan)


def quality_field(table: GraspTable, score: Numbers, grip_force: float) -> Field | None:
    """The ``quality`` field of each grasp, None when the table has no quality columns:
    ``{score, gravity_margin, hold_force_N, epsilon, contact: [{area_m2, type}] * 2}`` (``score``:
    the grasp's score column; ``hold_force_N``: :func:`hold_force` at the gripper's ``grip_force``,
    null when no force holds it), ``null`` for grasps without quality (gravity margin not finite)."""
    gm, eps, area, kind = table.gravity_margin, table.epsilon, table.contact_area, table.contact_type
    if gm is None:
        return None
    if eps is None or area is None or kind is None:
        raise ValueError("a GraspTable with gravity_margin needs epsilon, contact_area and contact_type too")

    def jaw(j: int) -> Record:
        return Record((Field("area_m2", Numbers(area[:, j], decimals=12)), Field("type", Names(kind[:, j], CONTACT_TYPES))))

    hold = hold_force(gm, grip_force)
    return Field("quality", Record((Field("score", score), Field("gravity_margin", Numbers(gm)),
                                    Field("hold_force_N", Numbers(hold, decimals=HOLD_FORCE_DECIMALS,
                                                                  null=lambda rows: np.isnan(hold[rows]))),
                                    Field("epsilon", Numbers(eps)), Field("contact", Items((jaw(0), jaw(1))))),
                                   null=lambda rows: ~np.isfinite(gm[rows])))


def sim_field(table: GraspTable) -> Field | None:
    """The ``sim`` field ``{success, slip_m, turn_deg}`` of the simulated grasps (absent on the
    others), None when the table has no simulation columns."""
    ok, slip, turn = table.sim_success, table.sim_slip_m, table.sim_turn_deg
    if ok is None:
        return None
    if slip is None or turn is None:
        raise ValueError("a GraspTable with sim_success needs sim_slip_m and sim_turn_deg too")
    return Field("sim", Record((Field("success", Bools(ok)), Field("slip_m", Numbers(slip)),
                                Field("turn_deg", Numbers(turn)))),
                 present=lambda rows: ok[rows] >= 0)


def _bad(where: str, i: int, g: Any, what: str) -> InputError:
    gid = g.get("id") if isinstance(g, dict) else None
    return InputError(f"{where}: grasps[{i}] (id {str(gid)[:20]}): {what}")


def parse_quality_sim(grasps: list[Any], where: str) -> dict[str, np.ndarray]:
    """GraspTable quality / sim columns from the grasp dicts of a file (keys absent: no columns);
    InputError naming the grasp for a malformed ``quality`` or ``sim`` object."""
    M = len(grasps)
    out: dict[str, np.ndarray] = {}
    qs = [g.get("quality") if isinstance(g, dict) else None for g in grasps]
    if any(q is not None for q in qs):
        cols = {"contact_area": np.full((M, 2), np.nan), "contact_type": np.full((M, 2), -1, dtype=np.int8),
                "gravity_margin": np.full(M, np.nan), "epsilon": np.full(M, np.nan)}
        for i, q in enumerate(qs):
            if q is None:
                continue
            try:
                gm, eps = float(q["gravity_margin"]), float(q["epsilon"])
                con = q["contact"]
                area = [float(c["area_m2"]) for c in con]
                kind = [CONTACT_TYPES.index(c["type"]) for c in con]
                hold = q.get("hold_force_N")  # derived (grip_force / gravity_margin): checked, not read
                ok = (len(con) == 2 and math.isfinite(gm) and gm >= 0 and math.isfinite(eps) and eps >= 0
                      and all(math.isfinite(a) and a >= 0 for a in area)
                      and not any(isinstance(v, bool) for v in (q["gravity_margin"], q["epsilon"], hold))
                      and (hold is None or (math.isfinite(float(hold)) and float(hold) >= 0)))
            except (KeyError, TypeError, ValueError, OverflowError, AttributeError):
                ok = False
            if not ok:
                raise _bad(where, i, grasps[i], "'quality' malformed; expected {score, gravity_margin >= 0, "
                           "hold_force_N >= 0 or null, epsilon >= 0, contact: [{area_m2 >= 0, type: "
                           "point|line|surface}] x 2} or null")
            cols["gravity_margin"][i], cols["epsilon"][i] = gm, eps
            cols["contact_area"][i], cols["contact_type"][i] = area, kind
        out.update(cols)
    ss = [g.get("sim") if isinstance(g, dict) else None for g in grasps]
    if any(x is not None for x in ss):
        succ, slip, turn = np.full(M, -1, dtype=np.int8), np.full(M, np.nan), np.full(M, np.nan)
        for i, x in enumerate(ss):
            if x is None:
                continue
            try:
                ok = isinstance(x["success"], bool) and all(
                    not isinstance(x[k], bool) and math.isfinite(float(x[k])) and float(x[k]) >= 0
                    for k in ("slip_m", "turn_deg"))
            except (KeyError, TypeError, ValueError, OverflowError):
                ok = False
            if not ok:
                raise _bad(where, i, grasps[i], "'sim' malformed; expected {success: bool, slip_m >= 0, "
                           "turn_deg >= 0} or null")
            succ[i], slip[i], turn[i] = int(x["success"]), float(x["slip_m"]), float(x["turn_deg"])
        out.update(sim_success=succ, sim_slip_m=slip, sim_turn_deg=turn)
    return out


def parse_mass_record(part: Any, where: str) -> dict[str, Any] | None:
    """The ``part`` mass record (``mass_kg``, ``com``, ``density``, ``mass_from``) of a file, None
    when absent; InputError when malformed."""
    if not isinstance(part, dict) or "mass_kg" not in part:
        return None
    try:
        m, d = float(part["mass_kg"]), float(part.get("density", "nan"))
        com = np.asarray(part["com"], dtype=np.float64)
        ok = m > 0 and math.isfinite(m) and com.shape == (3,) and np.all(np.isfinite(com))
    except (KeyError, TypeError, ValueError, OverflowError):
        ok = False
    if not ok:
        raise InputError(f"{where}: part.mass_kg must be a positive number and part.com three finite numbers (m)")
    out: dict[str, Any] = {"mass_kg": m, "com": com.tolist(), "density": d}
    if "material" in part:  # files before materials were recorded have none
        out["material"] = str(part["material"])
    out["mass_from"] = str(part.get("mass_from", "mesh"))
    return out
