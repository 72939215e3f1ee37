"""``grasplan view RESULT.json -o view.html [--part PATH]``: a self-contained HTML viewer."""
from __future__ import annotations

import warnings

import click

from .common import check_output, info, warn_all


@click.command("view")
@click.argument("result", type=click.Path(dir_okay=True))
@click.option("-o", "--output", "output", required=True, type=click.Path(dir_okay=False),
              help="The HTML file to write (one self-contained file; open it in any browser, no server needed).")
@click.option("--part", "part", type=click.Path(dir_okay=True), default=None,
              help="The part's mesh file. Default: part.path recorded in RESULT (a relative path is looked up "
                   "in the current folder, then next to RESULT). Its sha256 must match RESULT's.")
@click.option("--allow-other-part", is_flag=True,
              help="Draw a part whose sha256 differs from RESULT's (the grasps may not belong to it).")
@click.option("--instance", default=None,
              help="RESULT is a picks file (grasplan.picks/1, `grasplan pick`): show this instance's pick "
                   "(default: the first pick) with every other instance of the pile; a picks file without "
                   "a pick shows the pile and every instance's status and reason.")
def command(result: str, output: str, part: str | None, allow_other_part: bool, instance: str | None) -> None:
    """Write a self-contained HTML viewer for a grasps or plan file (RESULT).

    The page shows the part in its cell pose, the table, every grasp's contacts coloured by status,
    the selected grasp's gripper (jaws at the pre-grasp opening) and, for a plan, the robot at
    q_grasp with a button that plays the path home -> pre-grasp -> grasp. It makes no network
    request (three.js is bundled). RESULT is self-contained: no gripper, cell or robot YAML needed.
    """
    from ..results.reader import load_result
    from ..viewer.page import write_viewer

    output = check_output(output, result, part)
    info(f"view: {result}")
    from ..setup.outputs import picks_files, result_files
    from ..pick.reader import is_picks_file, load_picks, pick_as_plan, pile_as_plan

    notes: list[str] = []
    blockers: tuple[str, ...] = ()  # instances drawn as what blocks the shown one
    if is_picks_file(result):  # the pick as a one-grasp plan; the other instances are cell obstacles
        picks = load_picks(result)
        check_output(output, result, part, *picks_files(picks))  # the files it names are inputs too
        if picks.picks or instance is not None:
            res = pick_as_plan(picks, instance)
            blockers = tuple(picks.report(picks.pick(instance).instance).blocked_by)
        else:  # no pick: the pile, and why each instance cannot be picked
            res, notes = pile_as_plan(picks)
            blockers = tuple(picks.report(picks.scene.instances[0].id).blocked_by)
    elif instance is not None:
        from ..errors import InputError

        raise InputError(f"--instance: {result} is not a picks file (grasplan.picks/1 from `grasplan pick`)")
    else:
        res = load_result(result, part=part, allow_other_part=allow_other_part, verify_part=True)  # re-pointed part: refused
        check_output(output, result, part, *result_files(res))  # its part and robot files are inputs too
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        path = write_viewer(res, output, part_path=part, allow_other_part=allow_other_part, notes=notes,
                            blockers=blockers)
    warn_all(str(w.message) for w in caught)
    click.echo(f"wrote {path} ({path.stat().st_size / 1e6:.2f} MB)")
