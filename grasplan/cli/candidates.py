"""``grasplan candidates PART -o OUT.json``: BLM, convexity and antipodal contact pairs."""
from __future__ import annotations

import time
from typing import Any

import click

from ..errors import PlanningError
from ..config.params import CandidateParams, RunParams
from .common import check_output, info, table, units_option, warn_all
from .options import output_option, param_options


@click.command(
    help=(
        "Convex antipodal contact pairs for PART (Vogt et al. 2021): boundary layer mesher, convexity "
        "classification, antipodal search. Writes OUT as JSON (schema grasplan.candidates/1): contacts "
        "and normals in the part frame (file coordinates times scale_to_m), metres. Exit 4 (file still "
        "written) when no candidate is found."
    )
)
@click.argument("part", type=click.Path(dir_okay=True))
@output_option("JSON file to write (atomically; nothing is written on bad input).")
@param_options(CandidateParams)
@units_option
def command(part: str, output: str, units: str, **kwargs: Any) -> None:
    from ..candidates.pipeline import compute_candidates
    from ..io import write_json
    from ..part.mesh import load_part

    output = check_output(output, part)
    params = RunParams.from_options(kwargs, (CandidateParams,)).candidates
    info(f"grasplan candidates {part}")
    t0 = time.perf_counter()
    p = load_part(part, units=units)
    t_load = time.perf_counter() - t0
    info(p.units_note)
    warn_all(p.warnings)

    result = compute_candidates(p, params, load_s=t_load)
    for note in result.notes:
        info(note)
    write_json(output, result.to_json())

    counts, timing = result.counts(), result.timing_s
    rows = [
        ("units", p.units_note),
        ("triangles in", counts["triangles_in"]),
        ("triangles after BLM", counts["triangles_blm"] if counts["triangles_blm"] is not None else "- (--no-blm)"),
        ("convex faces", counts["convex_faces"]),
        ("candidates", counts["candidates"]),
    ]
    rows += [(f"{k} (s)", float(v)) for k, v in timing.items()]
    rows.append(("total (s)", float(sum(timing.values()))))
    click.echo(table(rows, header=("candidates", str(part)[:80])))
    click.echo(f"wrote {output}")
    if counts["candidates"] == 0:
        raise PlanningError(f"no antipodal candidate found for {part}; {output} is written (empty). Try a larger "
                            "--max-opening or --epsilon, or check the part's units")
