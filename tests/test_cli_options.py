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

from grasplan.cli import COMMANDS, main
from grasplan.cli import __name__ as cli_pkg

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
    plan = str(tmp_path / "missing_plan.json")
    base = {"export": [plan], "view": [plan], "simulate": [plan]}.get(command, [str(tmp_path / "missing_input.stl")])
    args = [command, *base, opt.opts[0], value]
    if command == "export" and opt.opts[0] != "--format":
        args += ["--format", "csv"]
    out = {"blm": "out.stl", "batch": "out_dir"}.get(command, "out.json")
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
