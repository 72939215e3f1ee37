"""``grasplan scene drop --cell bin --part PATH:COUNT ... -o scene.yaml``: a pile made in physics."""
from __future__ import annotations

import math
import time
from pathlib import Path

import click

from ..sim.drop import DropParams
from ..errors import InputError
from .common import check_output, info, table, units_option, warn_all
from .options import apply_config_dirs, config_dir_option, output_option, param_options


@click.group("scene")
def command() -> None:
    """Make scenes (grasplan.scene/1): many parts at poses in a cell."""


def parse_part_count(text: str) -> tuple[str, int, str | None]:
    """``PATH:COUNT`` or ``PATH:COUNT:MATERIAL`` -> (path, count, material or None); InputError
    (exit 3) naming what would pass (an unknown material lists the valid names)."""
    from ..config.materials import MATERIAL_NAMES, material_density
    from ..sim.drop import MAX_COUNT

    path, sep, count = str(text).rpartition(":")
    material = None
    if sep and count.strip().lower() in MATERIAL_NAMES or (sep and not count.strip().isdigit()
                                                            and path.rpartition(":")[2].strip().isdigit()):
        material = count.strip()
        material_density(material, option=f"--part {text}")
        path, sep, count = path.rpartition(":")
    if not sep or not path.strip():
        raise InputError(f"--part {text!r}: expected PATH:COUNT or PATH:COUNT:MATERIAL, e.g. --part "
                         f"parts/TLess20.stl:3 or parts/TLess20.stl:3:plastic")
    try:
        n = int(count.strip())
    except ValueError:
        raise InputError(f"--part {text!r}: the count {count!r} is not a whole number; expected PATH:COUNT, "
                         f"e.g. {path}:3") from None
    if not 1 <= n <= MAX_COUNT:
        raise InputError(f"--part {text!r}: the count must be 1..{MAX_COUNT}, got {n}")
    return path, n, material.lower() if material is not None else None


@command.command("drop")
@click.option("--cell", default="bin", show_default=True,
              help="Cell with a bin: a name (see --config-dir) or a cell YAML path.")
@click.option("--part", "parts", multiple=True, required=True, metavar="PATH:COUNT[:MATERIAL]",
              help="A part's mesh file, how many to drop and optionally its material (else --material's; "
                   "repeatable; one per part). The part is named by the file's stem as written (TLess20.stl -> "
                   "TLess20, instances TLess20_0, ...), as `grasplan serve` names it.")
@units_option
@param_options(DropParams)
@config_dir_option
@output_option("The scene file to write (grasplan.scene/1): YAML (.yaml, .yml) or JSON (.json) by the suffix.")
def drop(cell: str, parts: tuple[str, ...], units: str, output: str, **kwargs) -> None:
    """Drop parts into a bin one after another in MuJoCo and write the settled pile as a scene.

    Each part falls from a seeded random pose just above the pile (random orientation, random
    xy over the bin's floor) and the pile is simulated until every part is at rest (centre of
    mass < 5 mm/s, < 0.05 rad/s, for 0.2 s); parts collide through their CoACD convex pieces
    (computed once per part and cached, as by `grasplan simulate`). Mesh paths are written
    relative to the scene file. Exit 3 (nothing written) for bad input or a pile that does not fit
    the bin; exit 4 when the pile does not come to rest (try another --seed). docs/clutter.md.
    """
    from ..piles.scene_write import SCENE_SUFFIXES, write_scene
    from ..setup.resolved import build_setup
    from ..sim.drop import drop_pile, load_items

    t0 = time.perf_counter()
    if Path(output).suffix.lower() not in SCENE_SUFFIXES:
        raise InputError(f"-o {output}: a scene file is YAML or JSON; name it *.yaml, *.yml or *.json")
    specs = [parse_part_count(p) for p in parts]
    apply_config_dirs(kwargs)  # first: --config-dir decides which file the cell name reads
    check_output(output, *[s[0] for s in specs])  # the output itself first: nothing loads for a bad one
    params = DropParams(**kwargs)
    setup = build_setup(cell=cell)
    out = check_output(output, *[s[0] for s in specs], setup=setup)  # nor replaces the cell's files
    c = setup.cell
    assert c is not None  # build_setup(cell=...) loads one
    if c.bin is None:
        raise InputError(f"--cell {cell}: the cell has no bin to drop parts into; use a cell with a bin "
                         f"(e.g. --cell bin; docs/cells.md)")
    items = load_items(specs, units=units, info=info, warn=lambda w: warn_all([w]))
    total = sum(it.count for it in items)
    info(f"scene drop: {total} parts into {cell} (seed {params.seed}, {params.material} {params.density:g} kg/m^3, "
         f"mu {params.mu:g}); "
         f"convex pieces take minutes per part the first time, then come from the cache")

    floor = float(c.bin.T_world_bin[2, 3])

    def on_drop(d) -> None:
        tries = f", {d.attempts} tries" if d.attempts > 1 else ""
        info(f"  drop {d.index + 1}/{d.total} {d.id}: at rest after {d.settle_s:.2f} s simulated "
             f"({d.seconds:.1f} s{tries}), pile {1e3 * (d.top - floor):.0f} mm high")

    res = drop_pile(c, items, params=params, cell_ref=cell, progress=on_drop, log=lambda s: info(f"  {s}"))
    header = [f"grasplan scene drop: seed {params.seed}, {params.material} {params.density:g} kg/m^3, "
              f"mu {params.mu:g}, drop gap {params.drop_gap:g} m, {params.decomposition}; "
              f"settled in {res.sim_s:.2f} s simulated"]
    header += [f"part {n}: {r['path']} sha256 {r['sha256']} scale_to_m {r['scale_to_m']:g} ({r['count']} dropped)"
               for n, r in res.parts.items()]
    write_scene(out, res.scene, header=header)
    rows = []
    for inst in res.scene.instances:
        T = inst.T_world_part
        tilt = math.degrees(math.acos(max(-1.0, min(1.0, float(T[2, 2])))))
        rows.append((inst.id, inst.part, round(1e3 * T[0, 3], 1), round(1e3 * T[1, 3], 1), round(1e3 * T[2, 3], 1),
                     round(tilt, 1)))
    click.echo(table(rows, header=("id", "part", "x_mm", "y_mm", "z_mm", "tilt_deg")))
    click.echo(f"{total} parts settled in {res.sim_s:.2f} s simulated, {time.perf_counter() - t0:.1f} s; wrote {out}")
