"""``grasplan simulate PLAN_OR_GRASPS.json [--top N] -o OUT.json``: lift-and-shake check in MuJoCo."""
from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import click
import numpy as np

from ..errors import InputError
from ..config.params import GraspParams
from .common import check_output, info, table, warn_all
from .options import param_options

SCHEMA = "grasplan.sim/1"


@click.command("simulate")
@click.argument("result", type=click.Path(dir_okay=False, path_type=Path))
@click.option("-o", "--output", "output", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="The grasplan.sim/1 JSON file to write (atomically).")
@click.option("--top", type=click.IntRange(1, 10000), default=20, show_default=True,
              help="Simulate N grasps: a plan's planned grasps in rank order, else the best-scored "
                   "collision-free ones with the plan's diversity rule.")
@click.option("--part", "part", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="The part's mesh file. Default: part.path recorded in RESULT (sha256-checked).")
@click.option("--seed", type=click.IntRange(0, 2**31 - 1), default=0, show_default=True,
              help="Seed of the convex decomposition (the simulation itself is deterministic).")
@param_options(GraspParams, only=("material", "density", "mass"))
@click.option("--grip-force", "grip_force", type=click.FloatRange(min=0, min_open=True), default=None,
              help="Gripping force, N: the sum of both jaws' forces, as on a datasheet [default: the gripper's "
                   "grip_force].")
@click.option("--decomposition", type=click.Choice(("coacd", "hull")), default="coacd", show_default=True,
              help="Part collision shape: CoACD convex decomposition (cached) or the convex hull (fast, "
                   "exact only for convex parts).")
@click.pass_context
def command(ctx, result: Path, output: Path, top: int, part: Path | None, seed: int, material: str | None,
            density: float | None, mass: float | None, grip_force: float | None, decomposition: str) -> None:
    """Close, lift (10 cm in 0.5 s) and shake (+-5 m/s^2 along x then y for 1 s) the best grasps
    of a grasps or plan file in MuJoCo; a grasp holds when the part moved < 5 mm and turned < 5 deg
    relative to the jaws. Writes per grasp ``sim`` {success, slip_m, turn_deg} (grasplan.sim/1).
    Material, density and mass default to those the file was made with."""
    from ..io import write_json
    from ..part.mass import mass_properties
    from ..setup.outputs import result_files
    from ..results.reader import load_result
    from ..sim.simulate import LIFT_HEIGHT, LIFT_S, SHAKE_ACCEL, SHAKE_S, SLIP_TOL, TURN_TOL_DEG, simulate_result

    output = Path(check_output(output, result, part))
    if not result.exists():
        raise InputError(f"{result}: no such file (expected a grasplan grasps or plan JSON)")
    res = load_result(result, part=part, load_mesh=True)
    check_output(output, result, part, *result_files(res))  # its part and robot files are inputs too
    gp = res.params.grasps
    given = {k for k in ("material", "density", "mass")
             if ctx.get_parameter_source(k) not in (click.core.ParameterSource.DEFAULT, None)}
    if given:  # validated by GraspParams (InputError naming the option)
        kw = gp.to_json()
        if given & {"material", "density"}:
            kw.update(material=material, density=density)
        gp = GraspParams.from_json({**kw, **({"mass": mass} if "mass" in given else {})})
        res = replace(res, params=replace(res.params, grasps=gp))
    mp = mass_properties(res.mesh(), density=gp.density, mass=gp.mass, material=gp.material)
    warn_all(mp.warnings)
    info(f"simulate: {result} (mass {mp.mass:.3f} kg, mu {res.params.candidates.mu:g}, {decomposition})")
    rows, sim, mp, mu = simulate_result(res, top, mass_props=mp, grip_force=grip_force, seed=seed,
                                        decomposition=decomposition)
    g = res.grasps
    score = np.asarray(g.score, dtype=np.float64)
    ids = np.asarray(g.ids)[rows]
    doc = {
        "schema": SCHEMA,
        "source": {"path": str(result), "schema": res.schema},
        "part": {"path": res.part.path, "sha256": res.part.sha256, "scale_to_m": float(res.part.scale_to_m),
                 **mp.record()},
        "mass": mp.to_json(),
        "params": {"top": int(top), "seed": int(seed), "decomposition": decomposition, "mu": mu,
                   "grip_force": float(res.gripper.grip_force if grip_force is None else grip_force),
                   "grip_force_is": "sum of both jaws (each contact is pressed with half)",
                   "lift_height": LIFT_HEIGHT, "lift_s": LIFT_S, "shake_accel": SHAKE_ACCEL, "shake_s": SHAKE_S,
                   "slip_tol": SLIP_TOL, "turn_tol_deg": TURN_TOL_DEG},
        "counts": {"simulated": len(rows), "held": int(sim.success.sum())},
        "timing_s": {"simulate": float(sim.seconds)},
        "grasps": [{"id": int(ids[k]), "status": str(g.status[rows[k]]),
                    "score": None if math.isnan(score[rows[k]]) else float(score[rows[k]]),
                    "sim": sim.to_json(k)} for k in range(len(rows))],
    }
    write_json(output, doc)
    click.echo(table([(int(ids[k]), "held" if sim.success[k] else "slipped", round(1e3 * sim.slip_m[k], 2),
                       round(float(sim.turn_deg[k]), 2)) for k in range(len(rows))],
                     header=("id", "result", "slip_mm", "turn_deg")))
    click.echo(f"{int(sim.success.sum())}/{len(rows)} held; {sim.seconds:.1f} s; wrote {output}")
