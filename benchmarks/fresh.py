"""Shared by the benchmarks: run ``grasplan`` in a fresh interpreter, with its wall time and peak RSS."""
from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: runs the command line in a fresh interpreter and reports its peak RSS (VmHWM of its own address
#: space) last on stderr; ru_maxrss would also count the parent's pages from before exec
_CLI = r"""
import sys
from grasplan.cli import main
try:
    main(sys.argv[1:], prog_name="grasplan")
    rc = 0
except SystemExit as e:
    rc = e.code if isinstance(e.code, int) else (0 if e.code is None else 1)
hwm = [ln.split()[1] for ln in open("/proc/self/status") if ln.startswith("VmHWM:")]
sys.stderr.write("\nRSS_KIB %s\n" % (hwm[0] if hwm else "nan"))
sys.exit(rc)
"""


def bytecode_env(pycache: str, **extra: str) -> dict[str, str]:
    """This process's environment with bytecode caching on, as an installed package runs: when
    ``PYTHONDONTWRITEBYTECODE`` is set here, the bytecode goes to ``pycache`` instead; plus ``extra``."""
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    if "PYTHONDONTWRITEBYTECODE" in os.environ:
        env["PYTHONPYCACHEPREFIX"] = pycache
    env.update(extra)
    return env


def run_cli(args: list[str], env: dict[str, str] | None = None) -> tuple[float, int, float]:
    """(wall s, exit code, peak RSS MiB) of ``grasplan *args`` in a fresh interpreter (``env``: its
    environment, default this process's)."""
    t = time.perf_counter()
    p = subprocess.run([sys.executable, "-c", _CLI, *args], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                       text=True, cwd=ROOT, check=False, env=env)
    dt = time.perf_counter() - t
    rss = [ln for ln in p.stderr.splitlines() if ln.startswith("RSS_KIB ")]
    return dt, p.returncode, float(rss[-1].split()[1]) / 1024 if rss else float("nan")
