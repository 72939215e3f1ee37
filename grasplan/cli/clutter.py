"""``grasplan clutter --cell bin --part PATH:COUNT ... --rounds R --seed S -o report.json``: clutter
removal in physics (docs/clutter.md)."""
from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import click

from ..sim.drop import DropParams
from ..errors import InputError
from ..config.params import DEFAULT_GRIPPER, DEFAULT_ROBOT, GraspParams
from ..pick.params import PickParams
from .common import check_output, info, table, units_option, warn_all
from .options import apply_config_dirs, config_dir_option, output_option, param_options

#: the planner's options a clutter run passes on (the others are grasplan pick's defaults)
PICK_OPTIONS = ("lift_depth", "lift_contact", "lift_carry", "max_lift_tilt_deg")


def _pct(x) -> str:
    return "-" if x is None else f"{100 * x:.1f}"


@click.command("clutter")
@click.option("--cell", default="bin", show_default=True,
              help="Cell with a bin: a name (see --config-dir) or a cell YAML path.")
@click.option("--part", "parts", multiple=True, required=True, metavar="PATH:COUNT[:MATERIAL]",
              help="A part's mesh file, how many of it go into each pile and optionally its material (else "
                   "--material's; repeatable; one per part). The part is named by the file's stem as written "
                   "(TLess20.stl -> TLess20), as in `scene drop`.")
@units_option
@click.option("--rounds", type=click.IntRange(1, 1000), default=20, show_default=True,
              help="Piles to drop and clear; round r drops with seed --seed + r.")
@click.option("--pose-noise", "pose_noise", default="0,0", show_default=True, metavar="LENGTH,ANGLE",
              help="Pose estimate error: every part the planner sees is moved LENGTH in a random direction and "
                   "turned ANGLE about a random axis through its centre of mass (e.g. 2mm,2deg); 0,0: ground truth.")
@click.option("--robot", default=DEFAULT_ROBOT, show_default=True, help="Robot name or YAML path (the planner's).")
@click.option("--gripper", default=DEFAULT_GRIPPER, show_default=True, help="Gripper name or YAML path.")
@click.option("--view", "view", type=click.Path(dir_okay=False), default=None,
              help="Also write one HTML page replaying every round (the viewer's look; offline).")
@param_options(DropParams)
@param_options(PickParams, only=PICK_OPTIONS)
@config_dir_option
@output_option("The clutter report to write (grasplan.clutter/1 JSON, atomically).")
def command(cell: str, parts: tuple[str, ...], units: str, rounds: int, pose_noise: str, robot: str, gripper: str,
            view: str | None, output: str, **kwargs) -> None:
    """Clear piles in physics, as VGN measures clutter removal: GSR and DR.

    Each round drops a pile into the bin (as `grasplan scene drop`), then repeats: read the parts'
    poses (exact, or off by --pose-noise), plan with grasplan.Picker, execute the first pick in
    MuJoCo with the bin and every part present (the gripper's own shapes, jaws at the datasheet
    force, the TCP driven along the planned approach and lift; the arm is not simulated); success
    when the part is >= 5 cm up and between the jaws after a 1 s hold; it is then removed. A round
    ends when the bin is empty, after two failed attempts in a row, or when nothing is feasible.
    Writes per round and in total attempts, successes, GSR, DR, planning ms and failures by
    reason. Exit 3 (nothing written) for bad input. docs/clutter.md.
    """
    from ..clutter.execute import PROTOCOL
    from ..clutter.report import report_json, write_report
    from ..clutter.rounds import noise_reach, parse_pose_noise, run_round
    from ..pick import Picker
    from ..setup.resolved import build_setup
    from ..sim.drop import load_items, parts_record
    from .scene import parse_part_count

    t0 = time.perf_counter()
    noise = parse_pose_noise(pose_noise)
    specs = [parse_part_count(p) for p in parts]
    apply_config_dirs(kwargs)  # first: --config-dir decides which files the names below read
    inputs = [s[0] for s in specs]
    _check_outputs(output, view, inputs)  # the outputs themselves first: nothing loads for a bad one
    pick_kw = {k: kwargs.pop(k) for k in PICK_OPTIONS if k in kwargs}
    drop = DropParams(**kwargs)
    setup = build_setup(robot=robot, gripper=gripper, cell=cell)
    out, page = _check_outputs(output, view, inputs, setup)  # nor replace the setup's files
    c, g, rob = setup.cell, setup.gripper, setup.robot
    assert c is not None and g is not None and rob is not None  # build_setup loads each one it is given
    if c.bin is None:
        raise InputError(f"--cell {cell}: the cell has no bin to drop parts into; use a cell with a bin "
                         f"(e.g. --cell bin; docs/cells.md)")
    from ..clutter.world import pad_arc

    pad_arc(g)  # a linkage the clutter world cannot model: refused now (exit 3), not after the first drop
    items = load_items(specs, units=units, info=info, warn=lambda w: warn_all([w]))
    # the planner refuses parts below the bin floor by more than overlap_tol: pose noise moves them by up to this
    tol = PickParams.default("overlap_tol") + noise_reach([it.part for it in items], noise)
    # the grasp databases ranked for the parts' simulated mass (the gravity margin and the score depend on it)
    picker = Picker(rob, gripper=g, cell=c, params=PickParams(overlap_tol=min(tol, 0.05), **pick_kw),
                    database=GraspParams(material=drop.material, density=drop.density))
    for it in items:  # each part's grasp database at the density it is dropped with
        material, density = it.physics(drop)
        picker.add_part(it.name, it.part, material=material, density=density)
    n = sum(it.count for it in items)
    info(f"clutter: {rounds} rounds of {n} parts in {cell} (seed {drop.seed}, {drop.material} "
         f"{drop.density:g} kg/m^3, pose noise {noise[0] * 1e3:g} mm, {noise[1]:g} deg); "
         f"robot {picker.robot.name}, gripper {g.name}")

    results = []
    for r in range(rounds):
        rr = run_round(c, items, g, lambda s: picker.plan(s, max_picks=1), r=r, drop=drop, noise=noise, cell_ref=cell,
                       record=page is not None, cold=r == 0, progress=lambda s: info(f"  {s}"))
        results.append(rr)
        info(f"round {r + 1}/{rounds} (seed {rr.seed}): {rr.successes}/{len(rr.executed)} picks held, "
             f"{rr.removed}/{rr.parts} removed, ended: {rr.ended} ({rr.seconds:.1f} s)")
    params = {**drop.to_json(), "rounds": rounds, "pose_noise_m": noise[0], "pose_noise_deg": noise[1],
              "pick": picker.params.to_json(), "protocol": PROTOCOL}
    doc = report_json(results, params=params, parts=parts_record(items, drop), cell=cell,
                      gripper=g.to_json(), robot=picker.robot.name)
    if page is not None:
        from ..clutter.replay import write_replay

        write_replay(page, results, {it.name: it.part for it in items}, g, c, total=doc["total"],
                     title=f"grasplan clutter: {', '.join(f'{it.name} x{it.count}' for it in items)}")
    write_report(out, doc)
    _print_summary(doc, f"{out}" + (f" and {page}" if page is not None else ""), time.perf_counter() - t0)


def _check_outputs(output: str, view: str | None, inputs: list[str], setup: Any = None) -> tuple[Path, Path | None]:
    """``-o`` and ``--view`` checked by the output guard against ``inputs`` and the ``setup``'s files;
    InputError when they name one file."""
    out = check_output(output, *inputs, setup=setup)
    page = None if view is None else check_output(view, *inputs, setup=setup, option="--view")
    if page is not None and Path(page).resolve() == Path(out).resolve():
        raise InputError(f"--view {view}: the same file as -o {output}; give the page its own name (e.g. clutter.html)")
    return Path(out), None if page is None else Path(page)


def _print_summary(doc: dict[str, Any], wrote: str, seconds: float) -> None:
    """The per-round table, GSR, DR and failures of a clutter report ``doc`` on stdout."""
    rows = []
    for rj in doc["rounds"]:
        pm = rj["plan_ms"]["median"]
        rows.append((rj["round"] + 1, rj["seed"], rj["parts"], rj["attempts"], rj["successes"], _pct(rj["gsr"]),
                     _pct(rj["dr"]), rj["ended"], "-" if pm is None else round(pm), round(rj["seconds"], 1)))
    tot = doc["total"]
    pm = tot["plan_ms"]["median"]
    rows.append(("all", "", tot["parts"], tot["attempts"], tot["successes"], _pct(tot["gsr"]), _pct(tot["dr"]),
                 "", "-" if pm is None else round(pm), round(tot["seconds"], 1)))
    click.echo(table(rows, header=("round", "seed", "parts", "attempts", "held", "GSR_%", "DR_%", "ended",
                                   "plan_ms_median", "s")))
    fails = ", ".join(f"{k} {v}" for k, v in tot["failures"].items() if v) or "none"
    click.echo(f"GSR {_pct(tot['gsr'])} %, DR {_pct(tot['dr'])} %; failures: {fails}; {seconds:.1f} s; wrote {wrote}")

