"""The offline HTML viewer of a grasps, plan or picks result (:mod:`.page`)."""
from __future__ import annotations

from .._lazy import lazy_exports

__getattr__, __dir__ = lazy_exports(globals(), {
    "SCHEMAS": ".page",
    "STATUS_COLORS": ".page",
    "STATUS_ORDER": ".page",
    "OTHER_COLOR": ".page",
    "PATH_STEP_RAD": ".page",
    "MAX_SAMPLES_PER_PATH": ".page",
    "MAX_LINK_TRIANGLES": ".page",
    "MAX_PART_TRIANGLES": ".page",
    "LIST_CHUNK": ".page",
    "LIST_FULL": ".page",
    "encode_array": ".page",
    "decimate_mesh": ".page",
    "mesh_block": ".page",
    "shape_json": ".page",
    "densify_path": ".page",
    "build_data": ".page",
    "OBSTACLE_KINDS": ".page",
    "cell_data": ".page",
    "read_asset": ".page",
    "script_safe": ".page",
    "build_html": ".page",
    "write_viewer": ".page",
})
