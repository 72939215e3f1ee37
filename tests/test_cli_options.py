"""Every option of every command with 0, negative, NaN, huge and malformed values (issue 9): exit 2
(usage) or 3 (bad input) with a one-line message naming the option, never a traceback.

The PART / PLAN argument names a file that does not exist, so a value that is *valid* for an option
ends at the missing file (exit 3, the message names the file) without running the pipeline: the
walk stays fast and still tells accepted values from refused ones. The options' parse types and
ranges come from the parameter dataclasses, so the walk also pins their validation.
"""
from __future__ import annotations

import re

import click
import pytest
from click.testing import CliRunner

from grasplan.cli.group import COMMANDS
from grasplan.cli import main
from grasplan.cli import __name__ as cli_pkg
from grasplan.errors import InputError

BAD_VALUES = ("0", "-1", "nan", "inf", "1e308", "-1e308", "x!", "", "1e-300", "9" * 400)
#: library exception class names that must never reach the user
LEAKS = re.compile(r"Traceback|KeyError|IndexError|ValueError|TypeError|AttributeError|QhullError|MemoryError|"
                   r"ZeroDivisionError|OverflowError|RecursionError|internal error")


def _command(name):
    import importlib

    return importlib.import_module(f"{cli_pkg}.{COMMANDS[name][0]}").command


def _value_options():
    out = []
    for name in sorted(COMMANDS):
        cmd = _command(name)
        for p in cmd.params:
            if isinstance(p, click.Option) and not p.is_flag and not p.count and p.name not in ("output",):
                out.append((name, p))
    return out


OPTIONS = _value_options()


def test_every_command_has_options_to_walk():
    walked = {c for c, _ in OPTIONS}
    assert {"candidates", "grasps", "plan", "export", "view"} <= walked


def _args(command: str, tmp_path, opt: click.Option, value: str) -> list[str]:
    if command == "serve":  # no input file, no -o: a valid value ends at the missing --parts folder
        parts = [] if opt.opts[0] == "--parts" else ["--parts", str(tmp_path / "missing_parts")]
        return [command, *parts, opt.opts[0], value]
    if command == "clutter":  # no input argument: a valid value ends at the missing --part file
        part = [] if opt.opts[0] == "--part" else ["--part", f"{tmp_path / 'missing_input.stl'}:1"]
        return [command, *part, opt.opts[0], value, "-o", str(tmp_path / "out.json")]
    plan = str(tmp_path / "missing_plan.json")
    base = {"export": [plan], "view": [plan], "simulate": [plan]}.get(command, [str(tmp_path / "missing_input.stl")])
    args = [command, *base, opt.opts[0], value]
    if command == "export" and opt.opts[0] != "--format":
        args += ["--format", "csv"]
    out = {"blm": "out.stl", "batch": "out_dir", "fingers": "out.yaml"}.get(command, "out.json")
    return [*args, "-o", str(tmp_path / out)]


@pytest.mark.parametrize("command,opt", OPTIONS, ids=[f"{c}{o.opts[0]}" for c, o in OPTIONS])
def test_bad_values_exit_2_or_3_with_a_message(command, opt, tmp_path):
    runner = CliRunner()
    for value in BAD_VALUES:
        args = _args(command, tmp_path, opt, value)
        r = runner.invoke(main, args, catch_exceptions=True)
        text = r.output
        assert r.exception is None or isinstance(r.exception, SystemExit), (args, repr(r.exception))
        assert r.exit_code in (2, 3), (args, r.exit_code, text[-500:])
        assert not LEAKS.search(text), (args, text[-800:])
        msg = [ln for ln in text.splitlines() if ln.strip()]
        assert msg, (args, "no message")
        # the message names the option (refused) or the missing input (the value was accepted)
        assert any(o in text for o in opt.opts) or opt.name in text or "missing_" in text, (args, text[-500:])
        assert not any(tmp_path.glob("out*")), (args, "output written on error")


# -- one option schema: every surface reads an option's text the same way (issue 19) ------------------
def test_batch_offers_every_plan_option():
    """`grasplan batch` has every option of `grasplan plan` (the README's promise), with the same type."""
    plan, batch = _command("plan"), _command("batch")
    batch_opts = {o: p for p in batch.params if isinstance(p, click.Option) for o in p.opts}
    missing = [o for p in plan.params if isinstance(p, click.Option) and p.name != "output" for o in p.opts
               if o not in batch_opts]
    assert not missing, missing
    for p in plan.params:
        if isinstance(p, click.Option) and p.name != "output":
            assert type(batch_opts[p.opts[0]].type) is type(p.type), p.opts


#: texts per option kind: (text, False) is refused by every surface, (text, None) accepted or refused
#: by the field's range; the command line, a CSV manifest and a YAML manifest must give the same
#: value for each text, or all refuse it
TEXTS = {
    "length": [("2mm", None), ("0.004", None), ("1in", None), ("0", False), ("-1mm", False), ("5parsecs", False)],
    "length0": [("0", None), ("3mm", None), ("-1mm", False), ("x", False)],
    "angle": [("15", None), ("0.2rad", None), ("100deg", None), ("120", None), ("abc", False)],
    "float": [("0.5", None), ("2", None), ("2e3", None), ("15", None), ("nan", False), ("inf", False), ("x", False)],
    "seconds": [("30", None), ("0.5", None), ("nan", False)],
    "int": [("3", None), ("5", None), ("0", None), ("1.5", False), ("x", False), ("9" * 30, False)],
    "bool": [("yes", None), ("false", None), ("on", None), ("maybe", False)],
    "choice": [("paper", None), ("regions", None), ("PAPER", False)],
    "pose": [("0.45,0.3,0,0,0,180", None), ("450mm, 0.3, 0.1, 10, 0, 90", None), ("1,2,3", False),
             ("99,0,0,0,0,0", False)],
}


def _option_fields():
    from dataclasses import fields

    from grasplan.config.option_kinds import is_option
    from grasplan.config.params import PARAM_CLASSES

    return [(cls, f) for cls in PARAM_CLASSES for f in fields(cls) if is_option(f)]


@pytest.mark.parametrize("cls,f", _option_fields(), ids=[f.name for _, f in _option_fields()])
def test_cli_and_manifests_read_every_option_alike(cls, f, tmp_path):
    import csv
    import io

    import numpy as np

    from grasplan.batch.manifest import read_manifest
    from grasplan.errors import GrasplanError
    from grasplan.config.option_kinds import option_spec

    s = option_spec(f)
    texts = list(TEXTS.get(s.kind, []))
    if s.kind == "choice":  # this option's own choices (two of them) and one spelling it refuses
        texts = [(c, None) for c in s.choices[:2]] + [(s.choices[0].upper() + "x", False)]
    if s.kind == "file":
        (tmp_path / "w.yaml").write_text("weights: {top: 1}\n")
        texts = [(str(tmp_path / "w.yaml"), None), ("w.yaml", None),  # relative: to the manifest's folder
                 ("missing.yaml", False)]
    if s.optional:
        texts.append(("none", None))
    texts += [(w, None) for w in s.words]
    assert texts, f"no sample texts for kind {s.kind}"
    (tmp_path / "box.stl").write_bytes(b"solid x\nendsolid x\n")  # read_manifest only checks it exists
    cli_param = next(p for p in _command("batch").params if p.name == f.name)

    def by_cli(text):
        try:
            v = cli_param.type.convert(text, cli_param, None) if s.kind != "bool" else None
            if s.kind == "bool":  # a --x/--no-x flag on the command line: the manifest's words only
                return "flag"
            if s.kind == "file" and v is not None and not v.startswith("/"):
                v = str(tmp_path / v)  # the command line's folder is the manifest's here
            return ("ok", cls(**{f.name: v}))
        except (click.BadParameter, GrasplanError):
            return ("refused", None)

    def by_manifest(kind, text):
        if kind == "csv":
            buf = io.StringIO()
            csv.writer(buf).writerows([["path", f.name], ["box.stl", text]])
            m = tmp_path / "m.csv"
            m.write_text(buf.getvalue())
        else:
            m = tmp_path / "m.yaml"
            m.write_text(f"- {{path: box.stl, {f.name}: '{text}'}}\n")
        try:
            (entry,) = read_manifest(m)
            return ("ok", cls(**dict(entry.overrides)))
        except GrasplanError:
            return ("refused", None)

    accepted = 0
    for text, valid in texts:
        got = [by_manifest("csv", text), by_manifest("yaml", text)]
        cli = by_cli(text)
        if cli != "flag":
            got.append(cli)
        assert len({g[0] for g in got}) == 1, (f.name, text, got)
        assert valid is None or got[0][0] == "refused", (f.name, text, got)
        accepted += got[0][0] == "ok"
        values = [getattr(g[1], f.name) for g in got if g[1] is not None]
        if s.kind == "file":  # the file is read into the weights, recorded in the outputs
            values = [g[1].score_weights for g in got if g[1] is not None]
        assert all(np.array_equal(np.asarray(v, dtype=object), np.asarray(values[0], dtype=object))
                   for v in values), (f.name, text, values)
    assert accepted >= 2, (f.name, "fewer than two accepted texts: the comparison would prove little")


def test_new_options_leave_the_recorded_params_unchanged(tmp_path):
    """place and the scoring file are Params fields, yet a plan file records them where it did before
    (the place in cell.place, the scoring file as its weights): to_json is unchanged by them, and the
    batch's options JSON carries the place (it changes the result) but never the scoring file's name."""
    import numpy as np

    from grasplan.batch.options import BatchOptions
    from grasplan.config.params import GraspParams, PlanParams
    from grasplan.config.scoring import load_scoring
    from grasplan.geometry.transforms import parse_place

    T = parse_place("0.45,0.3,0,0,0,180")
    placed = PlanParams(place=T)
    assert placed.place == tuple(map(tuple, T.tolist())) and placed == PlanParams(place=T.tolist())
    assert placed.to_json() == PlanParams().to_json() and "place" not in placed.to_json()
    assert np.array_equal(placed.options_json()["place"], T) and "place" not in PlanParams().options_json()
    assert PlanParams.from_json(placed.options_json()) == placed
    (tmp_path / "s.yaml").write_text("weights: {top: 2, width: 1}\nnormalisation: {epsilon_ref: 0.2}\n")
    cfg = load_scoring(tmp_path / "s.yaml")
    scored = GraspParams(scoring=str(tmp_path / "s.yaml"))
    assert (scored.score_weights, scored.score_refs) == (cfg.weights, cfg.refs)
    assert scored.to_json() == GraspParams(score_weights=cfg.weights, score_refs=cfg.refs).to_json()
    assert "scoring" not in scored.to_json() and "scoring" not in scored.options_json()
    # the default options' JSON (the batch's options hash) is what it was: no new keys
    assert BatchOptions().to_json()["planning"] == PlanParams().to_json()
    assert BatchOptions().to_json()["grasps"] == GraspParams().to_json()
    with pytest.raises(InputError, match="--place"):
        PlanParams(place=np.diag([1.0, 1.0, -1.0, 1.0]))  # a reflection is no pose
    with pytest.raises(InputError, match="pose-index"):
        BatchOptions(grasps=GraspParams(pose_index="all"), T_world_part=np.eye(4))


def test_pose_index_all_is_refused_where_one_pose_is_planned(tmp_path):
    """``--pose-index all`` is for plan and batch; grasps (one resting pose) refuses it, exit 3, naming
    what would work, and writes nothing; the library's one-pose steps refuse it the same way."""
    from grasplan.config.params import GraspParams

    r = CliRunner().invoke(main, ["grasps", str(tmp_path / "missing_input.stl"), "--pose-index", "all",
                                  "-o", str(tmp_path / "out.json")])
    assert r.exit_code == 3 and "--pose-index all" in r.output and "grasplan plan" in r.output, r.output
    assert not (tmp_path / "out.json").exists()
    assert GraspParams(pose_index=2).single_pose_index() == 2 and GraspParams().single_pose_index() is None
    with pytest.raises(InputError, match="plan_poses"):
        GraspParams(pose_index="ALL".lower()).single_pose_index()
