"""``grasplan fingers PART --gripper NAME [-o GRIPPER.yaml]``: the finger window of a short-stroke gripper for a part."""
from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import click

from ..config.params import DEFAULT_GRIPPER, CandidateParams, GraspParams, PlanParams, RunParams
from ..errors import PlanningError
from .common import check_output, info, table, units_option, warn_all
from .options import apply_config_dirs, config_dir_option, param_options

@click.command(name="fingers")
@click.argument("part", type=click.Path(dir_okay=True))
@click.option("--gripper", default=DEFAULT_GRIPPER, show_default=True,
              help="A short-stroke gripper (a 'stroke:' in its YAML): a name (see --config-dir) or a YAML path.")
@click.option("--cell", default="table", show_default=True, help="Cell the part rests in (name or YAML path).")
@click.option("--windows", type=click.IntRange(1, 50), default=6, show_default=True,
              help="Windows counted in full: those holding the most candidate widths.")
@click.option("--name", "new_name", default=None,
              help="Name of the written gripper [default: GRIPPER_PARTSTEM].")
@click.option("-o", "--output", default=None, type=click.Path(dir_okay=False),
              help="Write the gripper YAML with the best window (atomically); without it, only the table.")
@units_option
@config_dir_option
@param_options(GraspParams, CandidateParams, exclude=("pose_index",))
def command(part: str, gripper: str, cell: str, windows: int, new_name: str | None, output: str | None, units: str,
            **kwargs: Any) -> None:
    """Rank the finger windows of a short-stroke GRIPPER for PART.

    A short-stroke gripper grips only widths in the window its fingers set (max_opening - stroke
    .. max_opening). For each window this counts PART's distinct grasps that are collision-free
    and predicted to hold, in each resting pose of probability >= 2 % on the cell's table,
    weighted by the pose's probability (the part's grasp database per window, cached), and
    prints the windows best first. -o writes the gripper's YAML with the best window's
    max_opening. Exit 4 when no window has a holdable grasp. Docs: docs/grippers.md."""
    from ..grasps.fingers import finger_windows, gripper_yaml
    from ..io import write_atomic_text
    from ..motion.planning import stable_pose_indices
    from ..part.mesh import load_part
    from ..setup.resolved import build_setup

    t0 = time.perf_counter()
    apply_config_dirs(kwargs)
    if output is not None:
        if Path(output).suffix.lower() not in (".yaml", ".yml"):
            raise click.BadParameter(f"{output}: a gripper YAML; give a name ending in .yaml or .yml",
                                     param_hint="'-o' / '--output'")
        check_output(output, part)
    prm = RunParams.from_options(kwargs, (CandidateParams, GraspParams))
    setup = build_setup(gripper=gripper, cell=cell)
    g, c, src = setup.gripper, setup.cell, setup.source("gripper")
    assert g is not None and c is not None
    p = load_part(part, units=units)
    info(f"fingers: {part} ({p.units_note}); gripper {g.name}, cell {c.name}")
    warn_all(p.warnings)
    poses = stable_pose_indices(p.mesh)
    pp = PlanParams()
    ranked = finger_windows(p, g, c, poses=poses, candidates=prm.candidates, grasps=prm.grasps, evaluate=windows,
                            distinct_distance=pp.distinct_distance, distinct_angle_deg=pp.distinct_angle_deg,
                            progress=info)
    rows = [(f"{w.min_opening * 1e3:.1f}-{w.max_opening * 1e3:.1f}", w.candidates, round(w.weighted, 2),
             " ".join(f"{k}:{n}" for k, _, n in w.per_pose)) for w in ranked]
    click.echo(table(rows, header=("window mm", "candidates", "holdable (weighted)", "per pose (index:grasps)")))
    click.echo("resting poses: " + ", ".join(f"{k} ({pr * 100:.1f} %)" for k, pr in poses)
               + f"; {time.perf_counter() - t0:.1f} s")
    if not ranked or ranked[0].weighted <= 0:
        raise PlanningError(f"no finger window of {g.name} gives {part} a grasp predicted to hold in any resting pose; "
                            "try a gripper with more force or stroke, or another --material / --density")
    best = ranked[0]
    if output is None:
        click.echo(f"best: max_opening {best.max_opening:.4f} m (window {best.min_opening * 1e3:.1f}-"
                   f"{best.max_opening * 1e3:.1f} mm); -o GRIPPER.yaml writes it")
        return
    if src is None or src.path is None:
        raise click.UsageError(f"gripper {g.name} was not read from a YAML file; give --gripper as a YAML path")
    stem = Path(p.path).stem
    name = new_name or f"{g.name}_{''.join(ch if ch.isalnum() else '_' for ch in stem)}"
    note = (f"fingers for {p.path} (sha256 {p.sha256[:12]}...): jaw window {best.min_opening * 1e3:.1f}-"
            f"{best.max_opening * 1e3:.1f} mm, {best.weighted:.1f} distinct holdable grasps weighted by resting-pose "
            f"probability (grasplan fingers)")
    write_atomic_text(output, gripper_yaml(src.path, best, name=name, note=note))
    click.echo(f"wrote {output} (gripper {name}, max_opening {best.max_opening:.4f} m)")
