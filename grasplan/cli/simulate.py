"""``grasplan simulate PLAN_OR_GRASPS.json [--top N] -o OUT.json``: lift-and-shake check in MuJoCo."""
from __future__ import annotations

import math
from pathlib import Path

import click
import numpy as np

from ..errors import InputError
from .common import info, table, warn_all

SCHEMA = "grasplan.sim/1"
#: statuses a grasp must have to be simulated (collision-free; in a plan, also the reachable ones)
SIMULATED_STATUSES = ("ok", "planned", "not_tried", "unreachable", "ik_collision", "no_path")


def select_grasps(status: np.ndarray, score: np.ndarray, top: int) -> np.ndarray:
    """Indices of the ``top`` collision-free grasps (statuses ``SIMULATED_STATUSES``), best score
    first (NaN scores last, ties by id)."""
    ok = np.flatnonzero(np.isin(status.astype(str), SIMULATED_STATUSES))
    s = np.where(np.isnan(score[ok]), -np.inf, score[ok])
    order = ok[np.lexsort((ok, -s))]
    return order[:top]


@click.command("simulate")
@click.argument("result", type=click.Path(dir_okay=False, path_type=Path))
@click.option("-o", "--output", "output", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="The grasplan.sim/1 JSON file to write.")
@click.option("--top", type=click.IntRange(1, 10000), default=20, show_default=True,
              help="Simulate the N best-scored collision-free grasps.")
@click.option("--part", "part", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="The part's mesh file. Default: part.path recorded in RESULT.")
@click.option("--seed", type=click.IntRange(0, 2**31 - 1), default=0, show_default=True,
              help="Seed of the convex decomposition (the simulation itself is deterministic).")
@click.option("--density", type=click.FloatRange(min=0, min_open=True), default=None,
              help="Part density, kg/m^3 [default: 7850, steel].")
@click.option("--mass", type=click.FloatRange(min=0, min_open=True), default=None,
              help="Part mass, kg (overrides --density).")
@click.option("--grip-force", "grip_force", type=click.FloatRange(min=0, min_open=True), default=None,
              help="Force per jaw, N [default: the gripper's grip_force].")
@click.option("--decomposition", type=click.Choice(("coacd", "hull")), default="coacd", show_default=True,
              help="Part collision shape: CoACD convex decomposition (cached) or the convex hull (fast, "
                   "exact only for convex parts).")
def command(result: Path, output: Path, top: int, part: Path | None, seed: int, density: float | None,
            mass: float | None, grip_force: float | None, decomposition: str) -> None:
    """Close, lift (10 cm in 0.5 s) and shake (+-5 m/s^2 along x then y for 1 s) the best grasps
    of a grasps or plan file in MuJoCo; a grasp holds when the part moved < 5 mm and turned < 5 deg
    relative to the jaws. Writes per grasp ``sim`` {success, slip_m, turn_deg}."""
    from ..io import write_json
    from ..mass import DEFAULT_DENSITY, mass_properties
    from ..params import CandidateParams
    from ..result import load_result
    from ..simulate import (
        LIFT_HEIGHT,
        LIFT_S,
        SHAKE_ACCEL,
        SHAKE_S,
        SLIP_TOL,
        TURN_TOL_DEG,
        simulate_grasps,
    )

    if not result.exists():
        raise InputError(f"{result}: no such file (expected a grasplan grasps or plan JSON)")
    res = load_result(result, part=part, load_mesh=True)
    mesh = res.part_mesh
    mp = mass_properties(mesh, density=DEFAULT_DENSITY if density is None else density, mass=mass)
    warn_all(mp.warnings)
    params = getattr(res, "params", None)
    mu = float(params.candidates.mu) if params is not None else float(CandidateParams.default("mu"))
    g = res.grasps
    score = np.asarray(g.score, dtype=np.float64)
    sel = select_grasps(np.asarray(g.status), score, top)
    if len(sel) == 0:
        raise InputError(f"{result}: no collision-free grasp to simulate (statuses: "
                         f"{', '.join(sorted(set(np.asarray(g.status).astype(str))))}); run grasps or plan first")
    info(f"simulate: {len(sel)} grasps of {result} (mass {mp.mass:.3f} kg, mu {mu:g}, {decomposition})")
    sim = simulate_grasps(mesh, res.gripper, res.T_world_part, g.T_part_tcp[sel], g.width[sel],
                          table_z=float(res.cell.table_z), mass_props=mp, grip_force=grip_force, mu=mu,
                          seed=seed, decomposition=decomposition)
    ids = np.asarray(g.ids)[sel]
    doc = {
        "schema": SCHEMA,
        "source": {"path": str(result), "schema": res.schema},
        "part": {"path": res.part.path, "sha256": res.part.sha256, "scale_to_m": float(res.part.scale_to_m)},
        "mass": mp.to_json(),
        "params": {"top": int(top), "seed": int(seed), "decomposition": decomposition, "mu": mu,
                   "grip_force": float(res.gripper.grip_force if grip_force is None else grip_force),
                   "lift_height": LIFT_HEIGHT, "lift_s": LIFT_S, "shake_accel": SHAKE_ACCEL, "shake_s": SHAKE_S,
                   "slip_tol": SLIP_TOL, "turn_tol_deg": TURN_TOL_DEG},
        "counts": {"simulated": len(sel), "held": int(sim.success.sum())},
        "timing_s": {"simulate": float(sim.seconds)},
        "grasps": [{"id": int(ids[k]), "score": None if math.isnan(score[sel[k]]) else float(score[sel[k]]),
                    "sim": sim.to_json(k)} for k in range(len(sel))],
    }
    write_json(output, doc)
    click.echo(table([(int(ids[k]), "held" if sim.success[k] else "slipped", round(1e3 * sim.slip_m[k], 2),
                       round(float(sim.turn_deg[k]), 2)) for k in range(len(sel))],
                     header=("id", "result", "slip_mm", "turn_deg")))
    click.echo(f"{int(sim.success.sum())}/{len(sel)} held; {sim.seconds:.1f} s; wrote {output}")
