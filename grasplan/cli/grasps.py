"""``grasplan grasps PART -o OUT.json``: gripper poses from candidates, filtered by collisions."""
from __future__ import annotations

import time

import click

from ..errors import InputError
from .common import ANGLE, LENGTH, LENGTH_OR_ZERO, info, table, units_option, warn_all


@click.command(name="grasps")
@click.argument("part", type=click.Path(dir_okay=False, path_type=str))
@click.option("-o", "--output", "output", required=True, type=click.Path(dir_okay=False, path_type=str),
              help="Output JSON file (grasplan.grasps/1), written atomically.")
@click.option("--gripper", default="schunk_egp_c_40", show_default=True,
              help="Gripper name (configs/grippers/NAME.yaml) or path to a gripper YAML.")
@click.option("--cell", default="table", show_default=True,
              help="Cell name (configs/cells/NAME.yaml) or path to a cell YAML.")
@click.option("--part-pose", default=None,
              help="Override the part's resting pose: 'x,y,z,roll,pitch,yaw' (lengths m or with units, "
                   "angles deg, R = Rz(yaw) Ry(pitch) Rx(roll)) or a JSON/YAML file with a 4x4 T_world_part.")
@click.option("--pose-index", type=click.IntRange(min=0), default=None,
              help="Rest the part in this stable pose (0 = most probable) instead of the cell's pose_index.")
@click.option("--roll-step", type=ANGLE, default=15.0, show_default=True,
              help="Roll step about the closing axis, degrees (poses at 0, step, ... < 360).")
@click.option("--thin", "thin_spacing", type=LENGTH_OR_ZERO, default=0.003, show_default="3mm",
              help="Pose only one candidate per cluster (grasp-centre grid of this pitch x closing axis in "
                   "10 deg steps, grasplan.thinning); 0 poses every candidate.")
@click.option("--merge-distance", type=LENGTH_OR_ZERO, default=0.0, show_default="0",
              help="Also skip a candidate whose contacts fall in the same grid cells of this size as an "
                   "earlier candidate's; 0 = off.")
@click.option("--no-blm", is_flag=True, help="Skip the boundary layer mesher.")
@click.option("--alpha", type=LENGTH, default=1e-4, show_default=True, help="BLM layer width (0.1mm).")
@click.option("--gamma", type=ANGLE, default=135.0, show_default=True, help="BLM surface angle, degrees.")
@click.option("--d-shift", type=LENGTH, default=1e-5, show_default=True, help="Convexity centroid shift (0.01mm).")
@click.option("--epsilon", type=LENGTH, default=5e-3, show_default=True, help="Antipodal overlap threshold (5mm).")
@click.option("--max-opening", type=LENGTH, default=None,
              help="Largest contact distance searched [default: the gripper's max_opening].")
@click.option("--mu", type=float, default=0.3, show_default=True, help="Friction coefficient.")
@click.option("--beta", type=ANGLE, default=2.0, show_default=True, help="Normals anti-parallel within this, degrees.")
@click.option("--only-ok", is_flag=True,
              help="Write only the ok grasps (counts still cover every pose); keeps files small.")
@click.option("--indent", type=int, default=None, help="Indent the JSON (default: compact).")
@units_option
def command(part, output, gripper, cell, part_pose, pose_index, roll_step, no_blm, alpha, gamma, d_shift, epsilon,
            max_opening, mu, beta, only_ok, indent, units, merge_distance, thin_spacing):
    """Gripper poses for PART's antipodal candidates, rolled about each closing axis, each checked
    for collisions of the gripper body and the closing jaws against the part and the table.

    Prints a summary (candidates, poses, kept, rejected by reason, seconds) and writes
    grasplan.grasps/1 JSON (docs/grasps.md)."""
    from ..candidates import CandidateParams
    from ..cell import load_cell, parse_part_pose
    from ..grasps import compute_grasps
    from ..gripper import load_gripper
    from ..io import write_json
    from ..mesh import load_part

    t_all = time.perf_counter()
    g = load_gripper(gripper)
    c = load_cell(cell)
    if pose_index is not None:
        from dataclasses import replace

        c = replace(c, pose_index=pose_index)
    T_world_part = parse_part_pose(part_pose) if part_pose is not None else None
    if not 0.0 < roll_step <= 360.0:
        raise InputError(f"--roll-step must be in (0, 360] degrees, got {roll_step}")
    try:
        params = CandidateParams(blm=not no_blm, alpha=alpha, gamma_deg=gamma, d_shift=d_shift, epsilon=epsilon,
                                 max_opening=max_opening,
                                 beta_deg=beta, mu=mu)
    except ValueError as exc:
        raise InputError(str(exc)) from None

    info(f"grasps: {part} (gripper {g.name}, cell {c.name})")
    t = time.perf_counter()
    p = load_part(part, units=units)
    load_s = time.perf_counter() - t
    info(f"  {p.units_note}")
    warn_all(p.warnings)
    res = compute_grasps(p, cand_params=params, gripper=g, cell=c, T_world_part=T_world_part,
                         roll_step_deg=roll_step, merge_distance=merge_distance,
                         thin_spacing=thin_spacing, load_s=load_s)
    doc = res.to_json()
    if only_ok:
        doc["grasps"] = [e for e in doc["grasps"] if e["status"] == "ok"]
        doc["only_ok"] = True
    t = time.perf_counter()
    write_json(output, doc, indent=indent)
    info(f"  wrote {output} in {time.perf_counter() - t:.2f} s")

    n = res.counts()
    rows = [
        ("candidates", n["candidates"]),
        ("posed candidates", n["posed_candidates"]),
        ("poses", n["poses"]),
        ("kept (ok)", n["ok"]),
        ("rejected: collision_part", n["collision_part"]),
        ("rejected: collision_table", n["collision_table"]),
    ]
    rows += [(f"seconds: {k}", float(v)) for k, v in res.timing_s.items()]
    rows.append(("seconds: total", time.perf_counter() - t_all))
    click.echo(table(rows))
    click.echo(f"wrote {output}")
