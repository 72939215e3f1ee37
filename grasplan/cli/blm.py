"""``grasplan blm PART -o OUT.stl``: insert the boundary layer and write the remeshed part."""
from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING

import click

from ..errors import InputError
from ..io import write_atomic_bytes
from ..config.params import CandidateParams
from .common import check_output, info, table, units_option, warn_all
from .options import param_options

if TYPE_CHECKING:
    import trimesh

#: output formats by suffix (trimesh exporter names)
OUTPUT_TYPES = {".stl": "stl", ".ply": "ply", ".obj": "obj"}


def export_bytes(mesh: trimesh.Trimesh, file_type: str) -> bytes:
    """Serialise ``mesh`` (binary STL / binary PLY / OBJ text) to bytes."""
    import trimesh.exchange.export  # trimesh loads when a mesh is written, not with --help

    data = trimesh.exchange.export.export_mesh(mesh, None, file_type=file_type)
    return data.encode("utf-8") if isinstance(data, str) else bytes(data)


def stamp_units(payload: bytes, file_type: str, note: str) -> bytes:
    """Record ``note`` (the output's units and scale) inside the mesh file: the 80-byte header of a
    binary STL (never starting with 'solid', which would read as ASCII STL), a comment in OBJ/PLY."""
    text = note.encode("ascii", "replace")
    if file_type == "stl":
        return text[:80].ljust(80, b" ") + payload[80:]
    if file_type == "obj":
        return b"# " + text + b"\n" + payload
    if file_type == "ply" and payload.startswith(b"ply\n"):
        first, rest = payload.split(b"\n", 2)[:2], payload.split(b"\n", 2)[2]
        return b"\n".join(first) + b"\ncomment " + text + b"\n" + rest
    return payload


@click.command(
    help=(
        "Insert the boundary layer (Vogt et al. 2021, Sec. III-A) into PART's mesh and write the "
        "remeshed part to OUT. The geometry is unchanged: only faces along surface boundaries are "
        "subdivided. OUT is written in metres, like every grasplan output, and its header records "
        "the units; --output-units mm (or the file's own units, 'input') writes it back in CAD units."
    )
)
@click.argument("part", type=click.Path(path_type=Path))
@click.option(
    "-o",
    "--output",
    "output",
    required=True,
    type=click.Path(dir_okay=False, path_type=Path),
    help="Remeshed part to write (.stl binary, .ply or .obj); written atomically.",
)
@click.option(
    "--output-units",
    type=click.Choice(["m", "mm", "cm", "um", "in", "ft", "input"]),
    default="m",
    show_default=True,
    help="Units of OUT's coordinates; 'input' = the part file's units (recorded in OUT's header).",
)
@param_options(CandidateParams, only=("alpha", "gamma_deg"))
@units_option
def command(part: Path, output: Path, alpha: float, gamma_deg: float, units: str, output_units: str) -> None:
    from ..candidates.blm import boundary_layer
    from ..part.mesh import load_part

    suffix = output.suffix.lower()
    if suffix not in OUTPUT_TYPES:
        raise InputError(f"{output}: unsupported output type {output.suffix or '(none)'!r}; use one of {', '.join(OUTPUT_TYPES)}")
    output = Path(check_output(output, part))
    prm = CandidateParams(alpha=alpha, gamma_deg=gamma_deg)  # the one range check of both options
    alpha, gamma_deg = prm.alpha, prm.gamma_deg

    t0 = time.perf_counter()
    p = load_part(part, units=units)
    t_load = time.perf_counter() - t0
    info(p.units_note)
    warn_all(p.warnings)

    t0 = time.perf_counter()
    r = boundary_layer(p.mesh, alpha=alpha, gamma_deg=gamma_deg, tol=p.tol)
    t_blm = time.perf_counter() - t0

    from ..geometry.units import LENGTH_UNITS

    unit = p.units if output_units == "input" else output_units
    m_per_unit = LENGTH_UNITS[unit]
    import trimesh

    out_mesh = trimesh.Trimesh(vertices=r.mesh.vertices / m_per_unit, faces=r.mesh.faces, process=False)
    note = (f"grasplan blm: units {unit} (scale_to_m {m_per_unit:g}); source {part.name} in {p.units} "
            f"(scale_to_m {p.scale_to_m:g}); alpha {alpha:g} m, gamma {gamma_deg:g} deg")
    payload = stamp_units(export_bytes(out_mesh, OUTPUT_TYPES[suffix]), OUTPUT_TYPES[suffix], note)
    write_atomic_bytes(output, payload)

    rows = [
        ("triangles in", p.triangles),
        ("triangles out", int(len(r.mesh.faces))),
        ("facets", r.facets),
        ("surfaces", r.surfaces),
        ("boundary edges", r.boundary_edges),
        ("shifted vertices", r.shifted_vertices),
        ("split faces", r.split_faces),
        ("clamped (face thinner than layer)", r.clamped),
        ("kept whole (already thin)", r.thin_kept + r.tiny_kept),
        ("alpha (mm)", float(alpha * 1e3)),
        ("gamma (deg)", float(gamma_deg)),
        ("load (s)", float(t_load)),
        ("blm (s)", float(t_blm)),
    ]
    click.echo(table(rows, header=("blm", str(part))))
    click.echo(f"wrote {output} (units {unit}, scale_to_m {m_per_unit:g}; recorded in its header)")
