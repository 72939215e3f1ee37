"""The result layering: grasplan.results.plan_result writes itself (result_writer) and exports itself
(export_registry) without importing the plan reader, the export package or Pinocchio, and
``PlanResult.export`` finds the format modules through the registry whatever was imported first."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def run(code: str) -> str:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=600, env=env)
    assert r.returncode == 0, r.stderr
    return r.stdout.strip()


def test_result_imports_no_reader_export_package_or_pinocchio():
    out = run("import sys, grasplan.results.plan_result\n"
              "print(sorted(m for m in ('grasplan.export', 'grasplan.results.reader', 'grasplan.grasps.pipeline', 'pinocchio') "
              "if m in sys.modules))")
    assert out == "[]"


def test_export_method_without_the_export_package(tmp_path):
    from test_export import mini_ur5, synthetic_plan

    from grasplan.export import render

    doc = synthetic_plan(mini_ur5())
    (tmp_path / "plan.json").write_text(json.dumps(doc))
    want = render(doc, "urscript")[".script"]
    out = run(f"""
import sys
from grasplan.results.reader import load_result
from grasplan.results.export_registry import FORMATS
res = load_result({str(tmp_path / 'plan.json')!r})
print('grasplan.export' in sys.modules, len(FORMATS))
res.export("urscript", {str(tmp_path / 'pick.script')!r})
print(sorted(FORMATS))
""")
    assert out.splitlines()[0] == "False 0"
    assert "urscript" in out.splitlines()[1] and "krl" in out.splitlines()[1]
    assert (tmp_path / "pick.script").read_text() == want
