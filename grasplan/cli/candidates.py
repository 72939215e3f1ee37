"""``grasplan candidates PART -o OUT.json``: BLM, convexity and antipodal contact pairs."""
from __future__ import annotations

import time
from pathlib import Path

import click

from ..errors import InputError
from .common import ANGLE, LENGTH, info, table, units_option, warn_all


@click.command(
    help=(
        "Convex antipodal contact pairs for PART (Vogt et al. 2021): boundary layer mesher, convexity "
        "classification, antipodal search. Writes OUT as JSON (schema grasplan.candidates/1): contacts "
        "and normals in the part frame (file coordinates times scale_to_m), metres."
    )
)
@click.argument("part", type=click.Path(path_type=Path))
@click.option("-o", "--output", "output", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="JSON file to write (atomically; nothing is written on bad input).")
@click.option("--blm/--no-blm", "blm", default=True, show_default=True,
              help="Run the boundary layer mesher before the search (--no-blm: search the part's own mesh).")
@click.option("--alpha", type=LENGTH, default="0.1mm", show_default=True,
              help="BLM boundary-layer width (0.1mm, 1e-4; a bare number is metres).")
@click.option("--gamma", "gamma_deg", type=ANGLE, default=135.0, show_default=True,
              help="BLM surface angle in degrees, in (90, 180]: facets join a surface when their normals "
              "deviate by at most 180 - gamma.")
@click.option("--d-shift", "d_shift", type=LENGTH, default="0.01mm", show_default=True,
              help="Convexity: shift of the auxiliary point (face centroid) along the face normal.")
@click.option("--epsilon", type=LENGTH, default="5mm", show_default=True,
              help="Overlap threshold: the centroid moved across the gap along the closing axis must land "
              "within this distance of the opposite centroid.")
@click.option("--max-opening", "max_opening", type=LENGTH, default="50mm", show_default=True,
              help="Gripper's maximum opening: contact pairs wider than this are dropped.")
@click.option("--mu", type=float, default=0.3, show_default=True,
              help="Friction coefficient: the closing axis must lie within atan(mu) of both inward normals.")
@click.option("--beta", "beta_deg", type=ANGLE, default=2.0, show_default=True,
              help="Normals must be anti-parallel within this angle (degrees).")
@units_option
def command(part: Path, output: Path, blm: bool, alpha: float, gamma_deg: float, d_shift: float,
            epsilon: float, max_opening: float, mu: float, beta_deg: float, units: str) -> None:
    from ..candidates import CandidateParams, compute_candidates
    from ..io import write_json
    from ..mesh import load_part

    try:
        params = CandidateParams(blm=blm, alpha=alpha, gamma_deg=gamma_deg, d_shift=d_shift, epsilon=epsilon,
                                 max_opening=max_opening, beta_deg=beta_deg, mu=mu)
    except ValueError as exc:
        raise InputError(f"bad option: {exc}") from exc

    info(f"grasplan candidates {part}")
    t0 = time.perf_counter()
    p = load_part(part, units=units)
    t_load = time.perf_counter() - t0
    info(p.units_note)
    warn_all(p.warnings)

    result = compute_candidates(p, params, load_s=t_load)
    doc = result.to_json()
    write_json(output, doc)

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
    if p.warnings:
        rows.append(("mesh warnings", len(p.warnings)))
    click.echo(table(rows, header=("candidates", str(part))))
    for w in p.warnings:
        click.echo(f"  warning: {w}")
    click.echo(f"wrote {output}")
