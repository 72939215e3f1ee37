"""``grasplan clutter --cell bin --part PATH:COUNT ... --rounds R --seed S -o report.json``: clutter
removal in physics (docs/clutter.md)."""
from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import click

from ..clutter.protocols import PROTOCOLS
from ..clutter.session import MIN_GRAVITY_MARGIN, PICK_OPTIONS
from ..sim.drop import DropParams
from ..errors import InputError
from ..config.params import DEFAULT_ROBOT, PAPER_GRIPPER
from ..pick.params import PickParams
from .common import check_output, info, table, units_option, warn_all
from .options import apply_config_dirs, config_dir_option, output_option, param_options


def _pct(x) -> str:
    return "-" if x is None else f"{100 * x:.1f}"


@click.command("clutter")
@click.option("--cell", default="bin", show_default=True,
              help="Cell with a bin: a name (see --config-dir) or a cell YAML path.")
@click.option("--protocol", type=click.Choice(tuple(PROTOCOLS)), default="bin", show_default=True,
              help="How piles are made and cleared: bin (dropped anywhere into the bin, picked from it), pile "
                   "(VGN's: dropped over the central third, bin removed), packed (VGN's: placed upright at free "
                   "spots, no bin). docs/clutter.md.")
@click.option("--part", "parts", multiple=True, required=True, metavar="PATH:COUNT[:MATERIAL]",
              help="A part's mesh file, how many of it go into each pile and optionally its material (else "
                   "--material's; repeatable; one per part). The part is named by the file's stem as written "
                   "(TLess20.stl -> TLess20), as in `scene drop`.")
@units_option
@click.option("--rounds", type=click.IntRange(1, 1000), default=20, show_default=True,
              help="Piles to drop and clear; round r drops with seed --seed + r.")
@click.option("--pose-noise", "pose_noise", default="0,0", show_default=True, metavar="LENGTH,ANGLE",
              help="Pose estimate error: every part the planner sees is moved LENGTH in a random direction and "
                   "turned ANGLE about a random axis through its centre of mass, one error per part and round "
                   "(e.g. 2mm,2deg); 0,0: ground truth.")
@click.option("--max-occlusion", "max_occlusion", type=click.FloatRange(0.0, 1.0, min_open=True), default=1.0,
              show_default=True, help="Parts an overhead camera sees at least this share of hidden (e.g. 0.8) are "
                                      "left out of the planner's scene; 1 plans every part.")
@click.option("--push/--no-push", "push", default=False, show_default=True,
              help="When no pick is planned, plan a push of a part a wall or a neighbour boxes in, execute it and "
                   "plan again (grasplan pick --push; pushes are not grasp attempts: the report lists them apart).")
@click.option("--robot", default=DEFAULT_ROBOT, show_default=True, help="Robot name or YAML path (the planner's).")
@click.option("--gripper", default=PAPER_GRIPPER, show_default=True, help="Gripper name or YAML path.")
@click.option("--view", "view", type=click.Path(dir_okay=False), default=None,
              help="Also write one HTML page replaying every round (the viewer's look; offline).")
@param_options(DropParams)
@param_options(PickParams, only=tuple(k for k in PICK_OPTIONS if k != "min_gravity_margin"))
@click.option("--min-gravity-margin", "min_gravity_margin", type=click.FloatRange(0.0, 100.0),
              default=MIN_GRAVITY_MARGIN, show_default=True,
              help="The planner plans only grasps whose gravity margin at the part's pose reaches this (1: predicted "
                   "to hold; 0: any grasp, as grasplan pick by default).")
@config_dir_option
@output_option("The clutter report to write (grasplan.clutter/1 JSON, atomically).")
def command(cell: str, protocol: str, parts: tuple[str, ...], units: str, rounds: int, pose_noise: str,
            max_occlusion: float, push: bool, robot: str, gripper: str, view: str | None, output: str,
            **kwargs) -> None:
    """Clear piles in physics, as VGN measures clutter removal: GSR and DR.

    Each round makes a pile by --protocol (bin: dropped into the bin as `grasplan scene drop`;
    pile: dropped over the bin's central third, then the bin is taken away; packed: placed
    upright on the table at free spots, no bin), then repeats: read the parts' poses (exact, or
    off by --pose-noise, one error per part and round; with --max-occlusion, parts the overhead
    camera barely sees are left out), plan with grasplan.Picker, execute the first pick in MuJoCo with
    every part present (the gripper's own shapes, jaws at the datasheet force, the TCP driven
    along the planned approach and lift, then straight up until the part clears the bin's rim, or
    10 cm above the table without the bin; the arm is not simulated). Success: after a 1 s hold the
    part is still between the jaws, clear, and turned at most 15 deg in them (else turned or
    dropped, counted apart); it is then removed. A round ends when the workspace is empty, after
    two failed attempts in a row, or when nothing is feasible. Writes per round and in total
    attempts, successes, GSR and DR with 95 % intervals, planning ms, failures by reason and the
    parts left. Exit 3 (nothing written) for bad input. docs/clutter.md.
    """
    from ..clutter.perception import parse_pose_noise
    from ..clutter.report import write_report
    from ..clutter.session import ClutterOptions, ClutterRun
    from ..setup.resolved import build_setup
    from .scene import parse_part_count

    t0 = time.perf_counter()
    noise = parse_pose_noise(pose_noise)
    specs = [parse_part_count(p) for p in parts]
    apply_config_dirs(kwargs)  # first: --config-dir decides which files the names below read
    inputs = [s[0] for s in specs]
    _check_outputs(output, view, inputs)  # the outputs themselves first: nothing loads for a bad one
    pick_kw = {k: kwargs.pop(k) for k in PICK_OPTIONS if k in kwargs}
    drop = DropParams(**kwargs)
    options = ClutterOptions(parts=tuple(specs), cell=cell, units=units, protocol=protocol, pose_noise=noise,
                             max_occlusion=max_occlusion, robot=robot, gripper=gripper, drop=drop, pick=pick_kw,
                             push=push)
    setup = build_setup(robot=robot, gripper=gripper, cell=cell)
    out, page = _check_outputs(output, view, inputs, setup)  # nor replace the setup's files
    run = ClutterRun(options, setup=setup, info=info, warn=lambda w: warn_all([w]))
    c, g, items = run.cell, run.gripper, run.items
    info(f"clutter: {rounds} rounds of {run.parts_per_round} parts, protocol {protocol}, in {cell} (seed {drop.seed}, "
         f"{drop.material} {drop.density:g} kg/m^3, pose noise {noise[0] * 1e3:g} mm, {noise[1]:g} deg"
         f"{'' if max_occlusion >= 1 else f', parts {100 * max_occlusion:g} % hidden left out'}); "
         f"robot {run.picker.robot.name}, gripper {g.name}")

    results = []
    for r in range(rounds):
        rr = run.round(r, record=page is not None, cold=r == 0, progress=lambda s: info(f"  {s}"))
        results.append(rr)
        info(f"round {r + 1}/{rounds} (seed {rr.seed}): {rr.successes}/{len(rr.executed)} picks held, "
             f"{rr.removed}/{rr.parts} removed, ended: {rr.ended} ({rr.seconds:.1f} s)")
    doc = run.report(results)
    if page is not None:
        from ..clutter.replay import write_replay

        write_replay(page, results, {it.name: it.part for it in items}, g, run.protocol.planner_cell(c),
                     total=doc["total"],
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
    ci = "".join(f" [{_pct(tot[k][0])}, {_pct(tot[k][1])}]" if tot[k] else "" for k in ("gsr_ci95",))
    dci = f" [{_pct(tot['dr_ci95'][0])}, {_pct(tot['dr_ci95'][1])}]" if tot["dr_ci95"] else ""
    pu = tot["pushes"]
    pushes = (f"; pushes {pu['n']} ({', '.join(f'{k} {v}' for k, v in pu['outcomes'].items())}), {pu['freed']} parts "
              f"freed") if pu["n"] else ""
    click.echo(f"GSR {_pct(tot['gsr'])} %{ci}, DR {_pct(tot['dr'])} %{dci} (95 % intervals); failures: {fails}"
               f"{pushes}; parts left {tot['left']['n']}; {seconds:.1f} s; wrote {wrote}")

