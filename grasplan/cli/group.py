"""The ``grasplan`` command line. Each command lives in its own module (``grasplan/cli/<name>.py``,
exposing a click command called ``command``) and is imported only when it runs, so ``--help`` is
fast and a heavy dependency (Pinocchio, OMPL) is loaded only by the commands that need it."""
from __future__ import annotations

import contextvars
import gc
import importlib
import os
import sys
from types import ModuleType

import click

from ..compiled.threads import one_blas_thread_here
from ..errors import GrasplanError

#: command name -> (module, one-line help shown by ``grasplan --help``; export's line lists the
#: registered formats, :func:`export_help`)
COMMANDS: dict[str, tuple[str, str]] = {
    "blm": ("blm", "Insert the boundary layer into a part's mesh and write the remeshed part."),
    "candidates": ("candidates", "Convex antipodal contact pairs for a part (BLM, convexity, antipodal)."),
    "grasps": ("grasps", "Gripper poses from candidates, filtered by full-jaw collision checks."),
    "database": ("database", "A part's grasp database: its grasps in the part frame, computed once for picking."),
    "fingers": ("fingers", "The finger window of a short-stroke gripper for a part: most holdable grasps over its poses."),
    "plan": ("plan", "Grasps a robot can reach: IK and collision-free approach paths."),
    "export": ("export", "Write a planned grasp as a robot program or data file."),
    "view": ("view", "Write a self-contained HTML viewer for a grasps or plan file."),
    "simulate": ("simulate", "Close, lift and shake grasps in MuJoCo; record which ones hold the part."),
    "batch": ("batch", "Plan a whole catalogue of parts (files, folders, manifests), locally or on Ray."),
    "scene": ("scene", "Make scenes of many parts: drop a pile into a bin in MuJoCo (scene drop)."),
    "pick": ("pick", "Plan picks from a pile of parts at known poses: bin, neighbours and cloud checked."),
    "clutter": ("clutter", "Clear piles in physics (drop, plan, pick in MuJoCo): grasp success and declutter rates."),
    "serve": ("serve", "An HTTP JSON service: picks, plans and robot programs from a warm planner."),
}


class LazyGroup(click.Group):
    def list_commands(self, ctx):
        return list(COMMANDS)

    def get_command(self, ctx, name):
        if name not in COMMANDS:
            return None
        return _import_command(f"grasplan.cli.{COMMANDS[name][0]}").command

    def format_commands(self, ctx, formatter):
        rows = [(name, export_help() if name == "export" else help_) for name, (_, help_) in COMMANDS.items()]
        with formatter.section("Commands"):
            formatter.write_dl(rows)

    def invoke(self, ctx):
        one_blas_thread_here()  # one BLAS thread unless the environment says otherwise (before NumPy loads)
        try:
            # a copied context: --config-dir (a context variable) ends with the command, so an
            # in-process caller (tests, batch workers) starts the next command with a clean lookup
            from .common import tolerant_stdout

            with tolerant_stdout():  # stdout closed or full after the outputs are written is no error
                return contextvars.copy_context().run(super().invoke, ctx)
        except GrasplanError as exc:
            click.echo(f"grasplan: error: {_one_line(str(exc))}", err=True)
            sys.exit(exc.exit_code)
        except (click.exceptions.Exit, click.ClickException, click.exceptions.Abort, SystemExit):
            raise
        except KeyboardInterrupt:
            click.echo("grasplan: interrupted; no output was written", err=True)
            sys.exit(130)
        except MemoryError:
            click.echo("grasplan: error: out of memory; the input is too large for this machine "
                       "(try a coarser mesh or a larger --spacing)", err=True)
            sys.exit(3)
        except RecursionError:
            click.echo("grasplan: error: the input is nested too deeply to read", err=True)
            sys.exit(3)
        except Exception as exc:  # a bug: one clear line, the traceback only on request
            if os.environ.get("GRASPLAN_DEBUG"):
                raise
            click.echo(f"grasplan: internal error ({type(exc).__name__}); no output was written. This is a bug: "
                       "please report it with the command line (GRASPLAN_DEBUG=1 shows the traceback)", err=True)
            sys.exit(1)


def _import_command(module: str) -> ModuleType:
    """``module``, imported; the first time, with the cyclic garbage collector paused, then what the
    imports made frozen (:func:`gc.freeze`: modules live as long as the process, and later
    collections need not walk them again)."""
    if module in sys.modules or not gc.isenabled():
        return importlib.import_module(module)
    gc.disable()
    try:
        return importlib.import_module(module)
    finally:
        gc.freeze()
        gc.enable()


def export_help() -> str:
    """``grasplan --help``'s line for export: the formats as registered (read only when help is shown)."""
    from ..results.export_registry import load_builtin_formats

    names = list(load_builtin_formats())
    return f"Write a planned grasp in one of {len(names)} formats: {', '.join(names)}."


def _one_line(msg: str, limit: int = 2000) -> str:
    """An error message as one line of printable text (inputs cannot forge further lines)."""
    msg = " ".join(msg.split())
    msg = "".join(c if c.isprintable() else "?" for c in msg)
    return msg if len(msg) <= limit else msg[: limit - 3] + "..."


@click.group(cls=LazyGroup, context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100})
@click.version_option(package_name="grasplan")
def main():
    """grasplan: verified parallel-jaw grasps from a part's CAD mesh.

    Lengths accept unit suffixes (0.1mm, 5cm); a bare number is metres. Angles are degrees.
    Exit codes: 0 ok, 2 usage error, 3 bad input (nothing written), 4 nothing usable found.
    """
