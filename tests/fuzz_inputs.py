"""Deterministic hostile-input cases for the reliability fuzz suite (issue 24): every YAML input
with values PyYAML cannot construct, alias bombs, deep nesting and duplicate keys; outputs that
would replace an input (every input kind, every spelling of the path, companions); FIFOs,
devices, folders and symlink loops for every input and for the files a mesh loader opens itself;
pose angles out of range; batch output folders and batch promises; re-pointed plans; the cell's
obstacle budget; stdout full or closed; SIGTERM during a batch.

Each :class:`InputCase` builds its inputs in an empty folder (``setup(folder, res) -> argv``) and
says which exit codes are right and which new files may appear. ``tests/test_fuzz_inputs.py``
runs them and checks, for every case: the exit code, no traceback or library error text, every
pre-existing file byte-identical afterwards, no leftover files, and a time limit. See docs/fuzz.md.
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
PARTS = ROOT / "examples" / "parts"
DATA = ROOT / "grasplan" / "data"
#: fast planning options for cases that plan
QUICK = ("--units", "mm", "--top", "1", "--roll-step", "90")


@dataclass(frozen=True)
class InputCase:
    """One case. ``setup(folder, res)`` creates the inputs in ``folder`` (``res``: shared
    resources, e.g. ``res["plan"]`` a plan file of box.stl) and returns the CLI arguments.
    ``outputs``: glob patterns (relative to ``folder``) of files that may appear on exit 0 or 4;
    ``after(folder)`` extra checks; ``mode``: "cli" (in-process), "stdout-full", "stdout-closed",
    "sigterm" (subprocesses)."""

    name: str
    family: str
    setup: Callable[[Path, dict], list[str]] = field(repr=False, compare=False)
    expect: frozenset[int] = frozenset({3})
    outputs: tuple[str, ...] = ()
    after: Callable[[Path], None] | None = field(default=None, repr=False, compare=False)
    mode: str = "cli"
    limit_s: float = 30.0
    heavy: bool = False  #: plans a part (seconds): only a few of these run in the default subset


def _box(folder: Path, name: str = "box.stl") -> Path:
    p = folder / name
    shutil.copy(PARTS / "box.stl", p)
    return p


def _write(folder: Path, name: str, text: str | bytes) -> Path:
    p = folder / name
    p.parent.mkdir(parents=True, exist_ok=True)
    if isinstance(text, bytes):
        p.write_bytes(text)
    else:
        p.write_text(text)
    return p


# ------------------------------------------------------------------------------------ YAML values
def _bomb(levels: int = 9) -> str:
    """A flow sequence of nested anchors: ``levels`` levels of 9 aliases each (9^levels leaves)."""
    items = ["&l0 [1, 1, 1, 1, 1, 1, 1, 1, 1]"]
    items += [f"&l{i} [" + ", ".join([f"*l{i - 1}"] * 9) + "]" for i in range(1, levels)]
    return "[" + ", ".join(items) + "]"


#: values no field accepts: (name, YAML text)
BAD_VALUES: tuple[tuple[str, str], ...] = (
    ("float-abc", "!!float abc"),
    ("bool-maybe", "!!bool maybe"),
    ("timestamp-x", "!!timestamp x"),
    ("int-5000-digits", "9" * 5000),
    ("alias-bomb", _bomb()),
    ("deep-150", "[" * 150 + "]" * 150),
    ("python-tag", "!!python/object/apply:os.system ['true']"),
    ("binary-bad-padding", "!!binary 'QQ'"),
    ("int-tag-on-float", "!!int 1.5"),
    ("merge-non-mapping", "{<<: 5}"),
    ("control-char", "a\x07b"),
)
#: values only a number field refuses (an ignored text field takes them)
NUMBER_ONLY: tuple[tuple[str, str], ...] = (
    ("date", "2001-13-45"),
    ("set", "!!set {a, b}"),
)


def _packaged_yaml(*parts: str) -> dict:
    return yaml.safe_load((DATA.joinpath(*parts)).read_text())


def _dump_with(doc: dict, path: tuple, placeholder: str = "@V@") -> str:
    """``doc`` as YAML with the value at ``path`` replaced by the placeholder (block style)."""
    d = json.loads(json.dumps(doc))
    node = d
    for k in path[:-1]:
        node = node[k]
    node[path[-1]] = placeholder
    return yaml.safe_dump(d, sort_keys=False).replace(f"'{placeholder}'", placeholder)


def _templates() -> list[tuple[str, str, str, bool]]:
    """(input kind, field, YAML text with @V@, is the field a number)."""
    gripper = _packaged_yaml("configs", "grippers", "schunk_egp_c_40.yaml")
    robot = _packaged_yaml("robots", "ur5.yaml")
    scoring = _packaged_yaml("configs", "scoring.yaml")
    return [
        ("cell", "table_z", "name: c\ntable_z: @V@\n", True),
        ("cell", "part_xy", "name: c\npart_xy: [@V@, 0.0]\n", True),
        ("cell", "retreat", "name: c\nretreat: {direction: [0, 0, 1], distance: @V@}\n", True),
        ("cell", "place", "name: c\nplace: {T: {xyz: [@V@, 0.0, 0.1]}}\n", True),
        ("cell", "obstacle-T", "name: c\nobstacles:\n  - {name: a, box: {size: [0.1, 0.1, 0.1]}, "
                               "T: {xyz: [0.3, @V@, 0.5]}}\n", True),
        ("cell", "description", "name: c\ndescription: @V@\n", False),
        ("gripper", "grip_force", _dump_with(gripper, ("grip_force",)), True),
        ("gripper", "max_opening", _dump_with(gripper, ("max_opening",)), True),
        ("gripper", "description", _dump_with({**gripper, "description": ""}, ("description",)), False),
        ("robot", "q_home", _dump_with(robot, ("q_home", 1)), True),
        ("robot", "description", _dump_with(robot, ("description",)), False),
        ("scoring", "weights.center", _dump_with(scoring, ("weights", "center")), True),
        ("scoring", "normalisation", _dump_with(scoring, ("normalisation", "epsilon_ref")), True),
        ("manifest", "pose_index", "parts:\n  - {path: box.stl, pose_index: @V@}\n", True),
        ("manifest", "defaults.units", "defaults: {units: @V@}\nparts: [box.stl]\n", True),
        ("part_pose", "T_world_part", "T_world_part: [[1, 0, 0, @V@], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]\n",
         True),
    ]


def _yaml_argv(kind: str, folder: Path, text: str) -> list[str]:
    """Write ``text`` as the ``kind`` input and return the command that reads it."""
    part = _box(folder)
    if kind == "manifest":
        m = _write(folder, "parts.yaml", text)
        return ["batch", str(m), "-o", str(folder / "out"), "--workers", "1", "--no-view"]
    name = {"part_pose": "pose.yaml"}.get(kind, f"{kind}.yaml")
    y = _write(folder, name, text)
    opt = {"part_pose": "--part-pose"}.get(kind, f"--{kind}")
    return ["plan", str(part), opt, str(y), "-o", str(folder / "out.json"), *QUICK]


def _embedded_robot(f: Path, r: dict, value: str) -> list[str]:
    """A plan whose embedded robot YAML (``robot.source.yaml``) holds ``value`` in ``description``."""
    doc = json.loads(Path(r["plan"]).read_text())
    text = doc["robot"]["source"]["yaml"]
    lines = [ln for ln in text.splitlines() if not ln.startswith("description:")]
    doc["robot"]["source"]["yaml"] = "\n".join(lines + [f"description: {value}"]) + "\n"
    p = _write(f, "plan.json", json.dumps(doc))
    return ["export", str(p), "--format", "urscript", "-o", str(f / "pick.script")]


def yaml_cases() -> list[InputCase]:
    out = [InputCase(f"yaml-embedded-robot-{vname}", "yaml_values", lambda f, r, v=value: _embedded_robot(f, r, v),
                     limit_s=20) for vname, value in BAD_VALUES]
    for kind, fld, tpl, numeric in _templates():
        values = BAD_VALUES + (NUMBER_ONLY if numeric and kind in ("cell", "part_pose") else ())
        for vname, value in values:
            text = tpl.replace("@V@", value)
            out.append(InputCase(f"yaml-{kind}-{fld}-{vname}", "yaml_values",
                                 lambda f, r, k=kind, t=text: _yaml_argv(k, f, t), limit_s=10))
        first = tpl.splitlines()
        dup = tpl + next((ln for ln in first if ln and not ln.startswith((" ", "-", "#"))), "name: x") + "\n"
        out.append(InputCase(f"yaml-{kind}-{fld}-duplicate-key", "yaml_values",
                             lambda f, r, k=kind, t=dup.replace("@V@", "1"): _yaml_argv(k, f, t), limit_s=10))
    return out


# ------------------------------------------------------------------------------------ output guard
def _spell(folder: Path, target: Path, how: str) -> str:
    """Another name for ``target``: plain, ./x, absolute, sub/../x, a symlink, a hard link."""
    if how == "plain":
        return str(target)
    if how == "dot":
        return str(target.parent / "." / target.name)
    if how == "updown":
        (folder / "sub").mkdir(exist_ok=True)
        return str(folder / "sub" / ".." / target.name)
    if how == "symlink":
        link = folder / f"link{target.suffix}"
        link.symlink_to(target)
        return str(link)
    if how == "hardlink":
        link = folder / f"hard{target.suffix}"
        os.link(target, link)
        return str(link)
    return os.path.relpath(target)


def _input_file(kind: str, folder: Path) -> tuple[Path, list[str]]:
    """An input of ``kind`` in ``folder`` and the options that read it."""
    if kind == "part":
        return folder / "box.stl", []
    if kind == "part_pose":
        p = _write(folder, "pose.json", json.dumps({"T_world_part": [[1, 0, 0, 0.45], [0, 1, 0, 0], [0, 0, 1, 0.005],
                                                                      [0, 0, 0, 1]]}))
        return p, ["--part-pose", str(p)]
    src = {"cell": DATA / "configs" / "cells" / "table.yaml",
           "gripper": DATA / "configs" / "grippers" / "schunk_egp_c_40.yaml",
           "robot": DATA / "robots" / "ur5.yaml", "scoring": DATA / "configs" / "scoring.yaml"}[kind]
    p = folder / f"{kind}.yaml"
    shutil.copy(src, p)
    return p, [f"--{kind}", str(p)]


def guard_cases() -> list[InputCase]:
    out = []
    for kind in ("part", "part_pose", "cell", "gripper", "robot", "scoring"):
        for how in ("plain", "dot", "updown", "symlink", "hardlink"):
            def setup(f, r, kind=kind, how=how):
                part = _box(f)
                target, opts = _input_file(kind, f)
                return ["plan", str(part), *opts, "-o", _spell(f, target, how), *QUICK]
            out.append(InputCase(f"guard-plan-o-is-{kind}-{how}", "output_guard", setup, limit_s=10))
    for kind in ("cell", "gripper", "robot"):  # by name through --config-dir
        def setup(f, r, kind=kind):
            part = _box(f)
            sub = {"cell": "cells", "gripper": "grippers", "robot": "robots"}[kind]
            src, _ = _input_file(kind, f)
            dst = f / "cfg" / sub / f"mine.yaml"
            dst.parent.mkdir(parents=True)
            shutil.move(src, dst)
            return ["plan", str(part), "--config-dir", str(f / "cfg"), f"--{kind}", "mine", "-o", str(dst), *QUICK]
        out.append(InputCase(f"guard-plan-o-is-config-dir-{kind}", "output_guard", setup, limit_s=10))
    for kind in ("scoring", "cell"):  # --pose-index all writes OUT.pose<k>.json next to OUT.json
        def setup(f, r, kind=kind):
            part = _box(f)
            src, _ = _input_file(kind, f)
            dst = f / "out.pose0.json"
            shutil.move(src, dst)
            return ["plan", str(part), f"--{kind}", str(dst), "--pose-index", "all", "-o", str(f / "out.json"), *QUICK]
        out.append(InputCase(f"guard-pose-all-companion-is-{kind}", "output_guard", setup, limit_s=10))

    def plan_copy(f: Path, r: dict, name: str = "plan.json") -> Path:
        p = f / name
        shutil.copy(r["plan"], p)
        return p

    def export_o_plan(fmt):
        return lambda f, r: ["export", str(plan_copy(f, r)), "--format", fmt, "-o", str(f / "plan.json")]
    for fmt in ("urscript", "csv", "joint-trajectory", "moveit-grasp"):
        out.append(InputCase(f"guard-export-{fmt}-o-is-plan", "output_guard", export_o_plan(fmt), limit_s=15))
    out.append(InputCase("guard-export-krl-dat-is-plan", "output_guard",
                         lambda f, r: ["export", str(plan_copy(f, r, "pick.dat")), "--format", "krl", "-o",
                                       str(f / "pick.src")], limit_s=15))

    def krl_dat_folder(f, r):
        plan = plan_copy(f, r)
        _write(f, "pick.src", "old program\n")
        (f / "pick.dat").mkdir()
        return ["export", str(plan), "--format", "krl", "-o", str(f / "pick.src")]
    out.append(InputCase("guard-export-krl-dat-is-folder-keeps-src", "output_guard", krl_dat_folder, limit_s=15))
    out.append(InputCase("guard-export-o-is-part", "output_guard",
                         lambda f, r: ["export", str(plan_copy(f, r)), "--format", "urscript", "--part",
                                       str(_box(f)), "-o", str(f / "box.stl")], limit_s=15))
    out.append(InputCase("guard-view-o-is-plan", "output_guard",
                         lambda f, r: ["view", str(plan_copy(f, r)), "-o", str(f / "plan.json")], limit_s=15))
    out.append(InputCase("guard-view-o-is-part", "output_guard",
                         lambda f, r: ["view", str(plan_copy(f, r)), "--part", str(_box(f)), "-o", str(f / "box.stl")],
                         limit_s=15))
    out.append(InputCase("guard-simulate-o-is-plan", "output_guard",
                         lambda f, r: ["simulate", str(plan_copy(f, r)), "-o", str(f / "plan.json")], limit_s=15))
    out.append(InputCase("guard-simulate-o-is-part", "output_guard",
                         lambda f, r: ["simulate", str(plan_copy(f, r)), "--part", str(_box(f)), "-o",
                                       str(f / "box.stl")], limit_s=15))
    out.append(InputCase("guard-grasps-o-is-cell", "output_guard",
                         lambda f, r: ["grasps", str(_box(f)), "--cell", str(_input_file("cell", f)[0]), "-o",
                                       str(f / "cell.yaml"), "--units", "mm"], limit_s=10))
    out.append(InputCase("guard-candidates-o-is-part", "output_guard",
                         lambda f, r: ["candidates", str(_box(f)), "-o", str(f / "box.stl")], limit_s=10))
    def o_is_obstacle_mesh(f, r):
        shutil.copy(PARTS / "box.stl", f / "ob.stl")
        argv = _obstacle_argv(f, "ob.stl")
        return argv[:argv.index("-o") + 1] + [str(f / "ob.stl")] + argv[argv.index("-o") + 2:]
    out.append(InputCase("guard-plan-o-is-obstacle-mesh", "output_guard", o_is_obstacle_mesh, limit_s=10))

    def o_is_gripper_mesh(f, r):
        shutil.copy(DATA / "configs" / "grippers" / "tapered_jaw.stl", f / "jaw.stl")
        argv = _gripper_mesh_argv(f, "jaw.stl")
        return argv[:argv.index("-o") + 1] + [str(f / "jaw.stl")] + argv[argv.index("-o") + 2:]
    out.append(InputCase("guard-grasps-o-is-gripper-mesh", "output_guard", o_is_gripper_mesh, limit_s=10))
    out += batch_folder_cases()
    return out


def _batch(f: Path, *extra: str, out: str = "out") -> list[str]:
    return ["batch", str(_box(f)), "-o", str(f / out), "--workers", "1", "--no-view", *QUICK, *extra]


def batch_folder_cases() -> list[InputCase]:
    """Bad batch output folders: every one refused up front (exit 3, nothing written)."""
    out = []

    def summary_manifest(f, r):
        _box(f)
        _write(f, "out/summary.csv", "path\n../box.stl\n")
        return ["batch", str(f / "out" / "summary.csv"), "-o", str(f / "out"), "--workers", "1"]
    out.append(InputCase("batch-manifest-is-out-summary-csv", "batch_folder", summary_manifest, limit_s=10))
    for name in ("summary.csv", "summary.json", "index.html"):
        def setup(f, r, name=name):
            (f / "out" / name).mkdir(parents=True)
            return _batch(f)
        out.append(InputCase(f"batch-{name}-is-a-folder", "batch_folder", setup, limit_s=10))

    def staging_file(f, r):
        _write(f, "out/.staging", "x")
        return _batch(f)
    out.append(InputCase("batch-staging-is-a-file", "batch_folder", staging_file, limit_s=10))

    def staging_link(f, r):
        _write(f, "target.txt", "keep me")
        (f / "out").mkdir()
        (f / "out" / ".staging").symlink_to(f / "target.txt")
        return _batch(f)
    out.append(InputCase("batch-staging-is-a-symlink", "batch_folder", staging_link, limit_s=10))

    def lock_folder(f, r):
        (f / "out" / ".grasplan-batch.lock").mkdir(parents=True)
        return _batch(f)
    out.append(InputCase("batch-lock-is-a-folder", "batch_folder", lock_folder, limit_s=10))

    def out_is_file(f, r):
        _write(f, "out", "a file")
        return _batch(f)
    out.append(InputCase("batch-o-is-a-file", "batch_folder", out_is_file, expect=frozenset({2, 3}), limit_s=10))
    for target in ("/proc/grasplan-fuzz", "/dev/null", "/sys/grasplan-fuzz"):
        out.append(InputCase(f"batch-o-under-{target.split('/')[1]}-{target.rsplit('/', 1)[1]}", "batch_folder",
                             lambda f, r, t=target: ["batch", str(_box(f)), "-o", t, "--workers", "1"], limit_s=10))

    def part_in_part_folder(f, r):
        sha = hashlib.sha256((PARTS / "box.stl").read_bytes()).hexdigest()
        d = f / "out" / f"box-{sha[:8]}"
        d.mkdir(parents=True)
        p = _box(d)
        return ["batch", str(p), "-o", str(f / "out"), "--workers", "1"]
    out.append(InputCase("batch-part-inside-its-result-folder", "batch_folder", part_in_part_folder, limit_s=10))

    def long_csv_field(f, r):
        _box(f)
        m = _write(f, "parts.csv", "path,units\nbox.stl," + "m" * 200_000 + "\n")
        return ["batch", str(m), "-o", str(f / "out"), "--workers", "1"]
    out.append(InputCase("batch-csv-field-200k-chars", "batch_folder", long_csv_field, limit_s=10))

    def csv_open_quote(f, r):
        _box(f)
        m = _write(f, "parts.csv", 'path,units\n"box.stl,mm\n' + "x" * 140_000 + "\n")
        return ["batch", str(m), "-o", str(f / "out"), "--workers", "1"]
    out.append(InputCase("batch-csv-unclosed-quote", "batch_folder", csv_open_quote, limit_s=10))
    for bad in ("1e308", "-1e308", "nan", "3601"):
        def setup(f, r, bad=bad):
            _box(f)
            m = _write(f, "parts.csv", f'path,place\nbox.stl,"0.4,0,0.1,{bad},0,0"\n')
            return ["batch", str(m), "-o", str(f / "out"), "--workers", "1"]
        out.append(InputCase(f"batch-manifest-place-angle-{bad}", "batch_folder", setup, limit_s=10))
        def setup2(f, r, bad=bad):
            _box(f)
            m = _write(f, "parts.csv", f'path,part_pose\nbox.stl,"0.4,0,0.1,0,{bad},0"\n')
            return ["batch", str(m), "-o", str(f / "out"), "--workers", "1"]
        out.append(InputCase(f"batch-manifest-part-pose-angle-{bad}", "batch_folder", setup2, limit_s=10))
    return out


# ------------------------------------------------------------------------------------ special files
def _special(f: Path, how: str, name: str) -> Path:
    """``f/name`` made a FIFO, a device link, a folder, a symlink loop, missing or a symlink to a FIFO."""
    p = f / name
    if how == "fifo":
        os.mkfifo(p)
    elif how in ("dev-zero", "dev-null", "dev-urandom"):
        p.symlink_to("/dev/" + how.split("-")[1])
    elif how == "folder":
        p.mkdir()
    elif how == "symlink-loop":
        p.symlink_to(f / (name + ".loop"))
        (f / (name + ".loop")).symlink_to(p)
    elif how == "link-to-fifo":
        os.mkfifo(f / (name + ".fifo"))
        p.symlink_to(f / (name + ".fifo"))
    return p  # "missing": nothing


SPECIALS = ("fifo", "dev-zero", "dev-null", "folder", "symlink-loop", "missing", "link-to-fifo")


def special_cases() -> list[InputCase]:
    out = []
    for how in SPECIALS:
        for kind, name in (("cell", "c.yaml"), ("gripper", "g.yaml"), ("robot", "r.yaml"), ("scoring", "s.yaml"),
                           ("part-pose", "pose.json")):
            out.append(InputCase(f"special-{kind}-{how}", "special_files",
                                 lambda f, r, k=kind, n=name, h=how: ["plan", str(_box(f)), f"--{k}",
                                                                      str(_special(f, h, n)), "-o",
                                                                      str(f / "out.json"), *QUICK],
                                 expect=frozenset({2, 3}), limit_s=10))
        out.append(InputCase(f"special-manifest-{how}", "special_files",
                             lambda f, r, h=how: ["batch", str(_special(f, h, "parts.csv")), "-o", str(f / "out")],
                             expect=frozenset({2, 3}), limit_s=10))
        for cmd in ("export", "view", "simulate"):
            extra = ["--format", "urscript"] if cmd == "export" else []
            out.append(InputCase(f"special-{cmd}-plan-{how}", "special_files",
                                 lambda f, r, h=how, c=cmd, e=extra: [c, str(_special(f, h, "plan.json")), *e, "-o",
                                                                      str(f / "out.txt")],
                                 expect=frozenset({2, 3}), limit_s=10))
        out.append(InputCase(f"special-obstacle-mesh-{how}", "special_files",
                             lambda f, r, h=how: _obstacle_argv(f, _special(f, h, "ob.stl").name),
                             expect=frozenset({3}), limit_s=10))
        out.append(InputCase(f"special-gripper-mesh-{how}", "special_files",
                             lambda f, r, h=how: _gripper_mesh_argv(f, _special(f, h, "jaw.stl").name),
                             expect=frozenset({3}), limit_s=10))
        # the files a mesh loader opens by itself: an OBJ's mtllib is ignored when not a regular file,
        # a glTF buffer that is not one is refused; neither may block or read a device
        out.append(InputCase(f"special-obstacle-obj-mtllib-{how}", "mesh_companions",
                             lambda f, r, h=how: _obstacle_argv(f, _obj_with_mtl(f, _special(f, h, "m.mtl").name),
                                                                command="grasps"),
                             expect=frozenset({0, 4}), outputs=("out.json",), limit_s=30, heavy=True))
        out.append(InputCase(f"special-part-gltf-buffer-{how}", "mesh_companions",
                             lambda f, r, h=how: ["candidates", str(_gltf(f, _special(f, h, "buf.bin").name)),
                                                  "-o", str(f / "out.json")], limit_s=10))
    for uri in ("http://127.0.0.1:9/x.bin", "/etc/hostname", "../../../../../../dev/zero", "data:,garbage"):
        out.append(InputCase(f"special-part-gltf-buffer-uri-{uri[:12].replace('/', '_')}", "mesh_companions",
                             lambda f, r, u=uri: ["candidates", str(_gltf(f, u)), "-o", str(f / "out.json")],
                             limit_s=10))
    for kind, name in (("scoring", "s.yaml"), ("cell", "c.yaml"), ("part-pose", "pose.json")):
        def big(f, r, k=kind, n=name):
            _write(f, n, "# " + "x" * 80 + "\n" * 1 + ("#" + "y" * 99 + "\n") * 21_000)
            return ["plan", str(_box(f)), f"--{k}", str(f / n), "-o", str(f / "out.json"), *QUICK]
        out.append(InputCase(f"special-{kind}-2MB", "special_files", big, limit_s=10))
    return out


def _obstacle_argv(f: Path, mesh_name: str, command: str = "plan") -> list[str]:
    c = _write(f, "cell.yaml", f"name: c\nobstacles:\n  - {{name: a, mesh: {{path: {mesh_name}}}, "
                               "T: {xyz: [0.3, 0.4, 0.6]}}\n")
    extra = QUICK if command == "plan" else ("--units", "mm", "--roll-step", "90")
    return [command, str(_box(f)), "--cell", str(c), "-o", str(f / "out.json"), *extra]


def _gripper_mesh_argv(f: Path, mesh_name: str) -> list[str]:
    doc = _packaged_yaml("configs", "grippers", "round_mesh_jaws.yaml")
    shutil.copy(DATA / "configs" / "grippers" / "round_body.stl", f / "round_body.stl")
    doc["fingers"]["mesh"]["path"] = mesh_name
    g = _write(f, "g.yaml", yaml.safe_dump(doc, sort_keys=False))
    return ["grasps", str(_box(f)), "--gripper", str(g), "-o", str(f / "out.json"), "--units", "mm"]


def _obj_with_mtl(f: Path, mtl: str) -> str:
    _write(f, "ob.obj", f"mtllib {mtl}\nv 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nv 0 0 0.1\nusemtl x\n"
                        "f 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n")
    return "ob.obj"


def _gltf(f: Path, uri: str) -> Path:
    doc = {"asset": {"version": "2.0"}, "buffers": [{"uri": uri, "byteLength": 108}],
           "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 108}],
           "accessors": [{"bufferView": 0, "componentType": 5126, "count": 9, "type": "VEC3",
                          "min": [0, 0, 0], "max": [1, 1, 1]}],
           "meshes": [{"primitives": [{"attributes": {"POSITION": 0}}]}], "nodes": [{"mesh": 0}],
           "scenes": [{"nodes": [0]}], "scene": 0}
    return _write(f, "part.gltf", json.dumps(doc))


# ------------------------------------------------------------------------------------ angles
BAD_ANGLES = ("1e308", "-1e308", "3601", "1e400", "nan", "inf", "-inf", "3600.001", "1e308deg")


def angle_cases() -> list[InputCase]:
    out = []
    for i, a in enumerate(BAD_ANGLES):
        rpy = ["0", "0", "0"]
        rpy[i % 3] = a
        pose = "0.45,0,0.1," + ",".join(rpy)
        for opt in ("--place", "--part-pose"):
            out.append(InputCase(f"angle{opt}-{a}-{'rpy'[i % 3]}", "angles",
                                 lambda f, r, o=opt, p=pose: ["plan", str(_box(f)), o, p, "-o", str(f / "out.json"),
                                                              *QUICK], expect=frozenset({2, 3}), limit_s=10))
    return out


# ------------------------------------------------------------------------------------ re-pointed plans
def _repoint(f: Path, r: dict, other: str) -> Path:
    doc = json.loads(Path(r["plan"]).read_text())
    if other == "box-moved":  # the same box, its vertices 5 mm off: every contact misses
        import numpy as np
        data = bytearray((PARTS / "box.stl").read_bytes())
        rec = np.frombuffer(bytes(data[84:]), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")]).copy()
        rec["v"][..., 0] += 5.0
        mesh = _write(f, "moved.stl", bytes(data[:84]) + rec.tobytes())
    else:
        mesh = f / f"{other}.stl"
        shutil.copy(PARTS / f"{other}.stl", mesh)
    doc["part"]["path"] = str(mesh)
    doc["part"]["sha256"] = hashlib.sha256(mesh.read_bytes()).hexdigest()
    return _write(f, "plan.json", json.dumps(doc))


def repoint_cases() -> list[InputCase]:
    out = []
    for other in ("gear", "bracket", "box-moved"):
        for cmd, extra in (("export", ["--format", "urscript"]), ("export", ["--format", "krl"]), ("view", []),
                           ("simulate", ["--decomposition", "hull", "--top", "1"])):
            o = "pick.src" if "krl" in extra else "out.txt"
            out.append(InputCase(f"repoint-{other}-{cmd}{'-krl' if 'krl' in extra else ''}", "repointed_plan",
                                 lambda f, r, c=cmd, e=extra, ot=other, o=o: [c, str(_repoint(f, r, ot)), *e, "-o",
                                                                              str(f / o)], limit_s=20))
    return out


# ------------------------------------------------------------------------------------ obstacle budget
def budget_cases() -> list[InputCase]:
    def many(f, r):
        obs = "".join(f"  - {{name: o{i}, box: {{size: [0.01, 0.01, 0.01]}}, T: {{xyz: [0.3, 0.4, {0.5 + i * 0.02:.2f}]}}}}\n"
                      for i in range(251))
        c = _write(f, "cell.yaml", "name: c\nobstacles:\n" + obs)
        return ["plan", str(_box(f)), "--cell", str(c), "-o", str(f / "out.json"), *QUICK]

    def big_mesh(n_faces: int, count: int):
        def setup(f, r):
            _write(f, "big.obj", "v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\n" + "f 1 2 3\n" * n_faces)
            obs = "".join(f"  - {{name: m{i}, mesh: {{path: big.obj}}, T: {{xyz: [0.3, 0.4, {0.5 + i * 0.1:.1f}]}}}}\n"
                          for i in range(count))
            c = _write(f, "cell.yaml", "name: c\nobstacles:\n" + obs)
            return ["plan", str(_box(f)), "--cell", str(c), "-o", str(f / "out.json"), *QUICK]
        return setup
    return [InputCase("budget-251-obstacles", "obstacle_budget", many, limit_s=10),
            InputCase("budget-one-mesh-260k", "obstacle_budget", big_mesh(260_000, 1), limit_s=10),
            InputCase("budget-two-meshes-130k", "obstacle_budget", big_mesh(130_000, 2), limit_s=20)]


# ------------------------------------------------------------------------------------ batch promises
def _first_batch(f: Path, *extra: str) -> Path:
    """Run a batch of box.stl into f/out in this process (the case then reruns it)."""
    from click.testing import CliRunner

    from grasplan.cli import main

    r = CliRunner().invoke(main, _batch(f, *extra))
    assert r.exit_code == 0, r.output[-400:]
    return next(p for p in (f / "out").iterdir() if p.is_dir() and p.name.startswith("box-"))


def _has(*names: str, absent: tuple[str, ...] = ()) -> Callable[[Path], None]:
    def check(f: Path) -> None:
        d = next(p for p in (f / "out").iterdir() if p.is_dir() and p.name.startswith("box-"))
        for n in names:
            assert (d / n).is_file(), f"{n} missing in {sorted(x.name for x in d.iterdir())}"
        for n in absent:
            assert not (f / "out" / n).exists(), f"{n} left in the output folder"
        done = json.loads((d / "done.json").read_text())
        assert done["status"] == "planned" and set(done["files"]) >= set(names)
    return check


BATCH_OUT = ("out", "out/**")


def promise_cases() -> list[InputCase]:
    out = [InputCase("promise-export-krl-rapid-written", "batch_promises",
                     lambda f, r: _batch(f, "--export", "krl,rapid,csv"), expect=frozenset({0}), outputs=BATCH_OUT,
                     after=_has("plan.json", "export_krl.src", "export_krl.dat", "export_rapid.mod", "export-csv.csv"),
                     limit_s=90, heavy=True)]

    def deleted(name):
        def setup(f, r):
            d = _first_batch(f)
            (d / name).unlink()
            return _batch(f)
        return setup
    for name in ("plan.json", "log.txt"):
        out.append(InputCase(f"promise-resume-after-{name}-deleted", "batch_promises", deleted(name),
                             expect=frozenset({0}), outputs=BATCH_OUT, after=_has("plan.json", "log.txt"),
                             limit_s=120, heavy=True))

    def damaged(how):
        def setup(f, r):
            d = _first_batch(f)
            done = d / "done.json"
            done.unlink()
            if how == "deep":
                done.write_text("[" * 100_000 + "]" * 100_000)
            elif how == "fifo":
                os.mkfifo(done)
            elif how == "huge":
                done.write_text(" " * 11_000_000 + "{}")
            elif how == "folder":
                done.mkdir()
            else:
                done.write_text('{"schema": "grasplan.batch-done/1", "status": "planned", "row": [], "files": 5}')
            return _batch(f)
        return setup
    for how in ("deep", "fifo", "huge", "wrong-types", "folder"):
        # a bad record affects only its part: it is planned again (and its record replaced)
        out.append(InputCase(f"promise-done-json-{how}", "batch_promises", damaged(how), expect=frozenset({0, 3}),
                             outputs=BATCH_OUT, limit_s=120, heavy=True,
                             after=None if how == "folder" else _has("plan.json")))

    def leftover_staging(f, r):
        _write(f, "out/.staging/box-deadbeef.0123abcd/plan.json", "{half")
        return _batch(f)
    out.append(InputCase("promise-staging-left-by-a-killed-run", "batch_promises", leftover_staging,
                         expect=frozenset({0}), outputs=BATCH_OUT, after=_has("plan.json", absent=(".staging",)),
                         limit_s=90, heavy=True))
    out.append(InputCase("promise-sigterm-cleans-staging", "batch_promises", lambda f, r: _batch(f, "--top", "3"),
                         expect=frozenset({143}), outputs=BATCH_OUT, mode="sigterm", limit_s=90, heavy=True,
                         after=lambda f: _no_staging(f)))
    return out


def _no_staging(f: Path) -> None:
    assert not (f / "out" / ".staging").exists(), "SIGTERM left OUTDIR/.staging"


# ------------------------------------------------------------------------------------ stdout
def stdout_cases() -> list[InputCase]:
    out = []
    for mode in ("stdout-full", "stdout-closed"):
        out.append(InputCase(f"{mode}-plan", "stdout", lambda f, r: ["plan", str(_box(f)), "-o", str(f / "out.json"),
                                                                     *QUICK],
                             expect=frozenset({0}), outputs=("out.json",), mode=mode, limit_s=90, heavy=True,
                             after=lambda f: json.loads((f / "out.json").read_text())))
        out.append(InputCase(f"{mode}-export", "stdout",
                             lambda f, r: ["export", str(shutil.copy(r["plan"], f / "plan.json")), "--format",
                                           "urscript", "-o", str(f / "pick.script")],
                             expect=frozenset({0}), outputs=("pick.script",), mode=mode, limit_s=90, heavy=True))
    return out


def input_cases() -> list[InputCase]:
    """Every case, in a fixed order (the generator has no randomness: the cases are the classes the
    issue names, crossed with every input, spelling and value)."""
    cases = (yaml_cases() + guard_cases() + special_cases() + angle_cases() + repoint_cases() + budget_cases()
             + promise_cases() + stdout_cases())
    names = [c.name for c in cases]
    assert len(names) == len(set(names)), "case names must be unique"
    return cases


def subset(cases: list[InputCase], per_family: int = 6, heavy: int = 3) -> list[InputCase]:
    """The default run: up to ``per_family`` light cases of every family, spread evenly over it,
    and ``heavy`` cases that plan (the full run is GRASPLAN_FUZZ_FULL=1)."""
    keep: list[InputCase] = []
    fams: dict[str, list[InputCase]] = {}
    for c in cases:
        if not c.heavy:
            fams.setdefault(c.family, []).append(c)
    for cs in fams.values():
        step = max(1, len(cs) // per_family)
        keep += cs[::step][:per_family]
    wanted = ("promise-export-krl-rapid-written", "promise-resume-after-plan.json-deleted", "stdout-full-export")
    keep += [c for c in cases if c.name in wanted][:heavy]
    return [c for c in cases if c in keep]
