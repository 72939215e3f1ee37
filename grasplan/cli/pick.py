"""``grasplan pick SCENE -o picks.json``: picks from a pile of known parts, planned against the bin,
the neighbours and a point cloud (docs/pick.md)."""
from __future__ import annotations

import time
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import click

from ..errors import PlanningError
from ..config.params import DEFAULT_GRIPPER, GraspParams
from ..pick.params import PickParams
from .common import check_output, info, table, warn_all
from .options import apply_config_dirs, config_dir_option, output_option, param_options, robot_option

if TYPE_CHECKING:
    from ..pick.result import InstanceReport


@click.command(name="pick")
@click.argument("scene", type=click.Path(dir_okay=False))
@robot_option
@click.option("--gripper", default=DEFAULT_GRIPPER, show_default=True,
              help="Gripper name (see --config-dir) or path to a gripper YAML.")
@click.option("--cell", default=None,
              help="Cell name or YAML path instead of the scene's own cell.")
@click.option("--sequence", is_flag=True, default=False,
              help="Plan a pick, remove that instance, plan the next, until none is left or none is feasible.")
@click.option("--max-picks", type=click.IntRange(1, 100000), default=None,
              help="Stop after this many picks (the other instances are not_tried).")
@click.option("--push", is_flag=True, default=False,
              help="When no instance can be picked, plan a push that moves a part a wall or a neighbour boxes in "
                   "into the open (the file's 'push' entry, with its joint path; docs/pick.md); re-plan after it.")
@param_options(PickParams)
@param_options(GraspParams, only=("material", "density"))
@config_dir_option
@output_option("Output JSON (grasplan.picks/1): the scene, robot, gripper and cell, every pick in pick order and "
               "every instance's status and reason.")
def command(scene: str, robot: str, gripper: str, cell: str | None, sequence: bool, max_picks: int | None,
            push: bool, output: str, **kwargs: Any) -> None:
    """Plan picks from the pile in SCENE (grasplan.scene/1): per instance its grasps posed in the
    world, checked against the bin, the table, the other instances and the cloud, ranked by score
    and accessibility (parts on top first), then IK, the straight approach, the transit and the lift
    checked against the neighbours. With --push, when nothing can be picked: a planned push of a
    part boxed in by a wall or a neighbour. Exit 4 (the file still written) when nothing can be
    picked (and, with --push, nothing pushed).
    """
    from ..config.lookup import document_ref
    from ..pick.picker import Picker
    from ..piles.scene_file import load_scene
    from ..setup.outputs import scene_files
    from ..setup.resolved import build_setup

    t0 = time.perf_counter()
    apply_config_dirs(kwargs)
    # the grasp databases computed (and cached) for the parts; a scene part's material or density wins
    database = GraspParams(material=kwargs.pop("material"), density=kwargs.pop("density"))
    params = PickParams(**kwargs)
    check_output(output, scene)  # the output itself first: nothing is read for a bad one
    sc = load_scene(scene)  # bad input: exit 3 before anything is computed
    # the robot, the gripper and the cell (--cell, else the scene's own, relative to the scene) loaded once
    setup = build_setup(robot=robot, gripper=gripper, cell=cell if cell is not None else document_ref(sc.cell, sc.base))
    # -o must not be any file the scene or the setup reads: meshes, grasp databases, the cloud, the YAMLs
    output = check_output(output, scene, *scene_files(sc), setup=setup)
    assert setup.robot is not None and setup.gripper is not None  # build_setup loads each one it is given
    picker = Picker(setup.robot, gripper=setup.gripper, cell=setup.cell, params=params, database=database,
                    progress=info)
    info(f"scene {scene}: {len(sc.instances)} instances of {len(sc.part_names())} parts")
    result = picker.plan(sc, sequence=sequence, max_picks=max_picks, push=push)
    warn_all(result.warnings)
    result.write(output)
    click.echo(instance_table(result.instances))
    order = " -> ".join(p.instance for p in result.picks) or "(none)"
    click.echo(f"{len(result.picks)} of {len(result.instances)} instances picked ({order}); wrote {output}")
    click.echo(table([(k, float(v)) for k, v in result.timing_s.items()] + [("wall", time.perf_counter() - t0)],
                     header=("stage", "seconds")))
    if result.push is not None:
        pu = result.push
        click.echo(f"push {pu.instance} {pu.distance * 1e3:.0f} mm away from {pu.against} (it kept {pu.gap * 1e3:.1f} mm "
                   f"from it); re-plan after the push")
    elif push and not result.picks:
        click.echo("no push either: " + ("; ".join(result.push_tried) or "no part is within reach of a wall or a "
                                        "neighbour"))
    if not result.picks and result.push is None:
        raise PlanningError(f"no instance of {scene} can be picked; {output} lists every instance's status and reason")


def instance_table(instances: Sequence[InstanceReport]) -> str:
    """The instances' table (id, part, status, blocked_by), with a footer saying what ``blocked_by``
    means for a picked and for a blocked instance when any instance has one."""
    rows = [(r.id, r.part, r.status.value, ",".join(r.blocked_by) or "-") for r in instances]
    text = table(rows, header=("instance", "part", "status", "blocked_by"))
    if any(r.blocked_by for r in instances):
        text += ("\nblocked_by: on a picked instance, the neighbours hit by its better-ranked grasps (it was picked "
                 "with a lower-ranked one); on any other, the neighbours its grasps, arm or lift hit")
    return text
