"""Configuration and inputs: finding grippers, cells and robots by name or path, the one YAML and
strict-JSON readers, opening input files, every option (frozen dataclasses), the score terms and
pose strings.

Every name below is imported from its module on first use (:mod:`grasplan._lazy`).
"""
from __future__ import annotations

from .._lazy import lazy_exports

__getattr__, __dir__ = lazy_exports(globals(), {
    "use_config_dirs": ".lookup", "resolve_yaml": ".lookup", "available": ".lookup",
    "is_path_like": ".lookup", "document_ref": ".lookup",
    "CandidateParams": ".params", "GraspParams": ".params", "PlanParams": ".params",
    "read_yaml_file": ".yamlfile", "load_yaml_text": ".yamlfile",
    "loads_strict": ".jsontext",
    "read_input_bytes": ".inputs",
    "load_scoring": ".scoring", "register_term": ".scoring",
    "parse_pose": ".poses", "parse_part_pose": ".poses",
})
