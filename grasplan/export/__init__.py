"""Robot-program and data exports of a plan (the last pipeline stage), one registry.

Every format is one module here that registers an :class:`~grasplan.results.export_registry.ExportFormat`
(name, file extension, one-line description, ``render(plan, options) -> {extension: text}``);
:data:`grasplan.results.export_registry.BUILTIN_MODULES` lists the shipped ones. :func:`write` and
:func:`render` take a PlanResult, a plan file or a parsed plan document; bad input is an
:class:`grasplan.errors.InputError` (CLI exit 3) and writes nothing: the whole output is rendered in
memory first, then each file is written atomically::

    plan = grasplan.load_result("plan.json")             # or the PlanResult of grasplan.plan(...)
    grasplan.export.write(plan, "urscript", "pick.script")          # best planned grasp
    grasplan.export.write(plan, "krl", "pick.src", grasp_id=17)     # writes pick.src and pick.dat
    plan.export("csv", "grasps.csv")
"""
from __future__ import annotations

from .._lazy import lazy_exports

__getattr__, __dir__ = lazy_exports(globals(), {
    "write": ".api", "render": ".api", "Plan": ".api",
    "FORMATS": "..results.export_registry", "ExportFormat": "..results.export_registry", "ExportOptions": "..results.export_registry", "register": "..results.export_registry",
    "get_format": "..results.export_registry", "load_builtin_formats": "..results.export_registry", "DEFAULT_MAX_ACCEL": "..results.export_registry",
    "output_paths": "..results.export_registry", "program_options": "..results.export_registry",
})
