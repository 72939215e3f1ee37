"""The convex pieces a part collides with in MuJoCo (:mod:`grasplan.sim.simulate`, the pile and clutter
worlds): a CoACD convex decomposition, cached per part geometry in ``$GRASPLAN_CACHE_DIR`` or
``~/.cache/grasplan`` (written atomically), or the part's convex hull."""
from __future__ import annotations

import hashlib
import io
import itertools
import warnings
from pathlib import Path

import numpy as np

from ..cache import cache_dir
from ..errors import InputError
from ..config.inputs import read_input_bytes
from ..io import write_atomic_bytes
from ..geometry.meshdata import TriangleMesh

#: CoACD settings: concavity threshold and the most pieces (-1: no limit). Merging down to a cap
#: (32 was tried) fills concavities: on TLess20 the jaws then start up to 4 mm inside a piece at the
#: pre-grasp opening and the part is pushed away (7 of the top 20 grasps "slipped"); uncapped (80
#: pieces) all 20 held and the decomposition was faster (no merging)
COACD_THRESHOLD, COACD_MAX_PIECES = 0.05, -1
DECOMPOSITIONS = ("coacd", "hull")


# ------------------------------------------------------------------------------------------------
# convex decomposition, cached
# ------------------------------------------------------------------------------------------------
def _mesh_key(mesh: TriangleMesh, extra: str) -> str:
    h = hashlib.sha256()
    h.update(np.ascontiguousarray(mesh.vertices, dtype=np.float64).tobytes())
    h.update(np.ascontiguousarray(mesh.faces, dtype=np.int64).tobytes())
    h.update(extra.encode())
    return h.hexdigest()


def convex_pieces(mesh: TriangleMesh, *, decomposition: str = "coacd", seed: int = 0,
                  cache: bool = True) -> list[np.ndarray]:
    """Vertices ``(n_i, 3)`` (m, part frame) of the convex pieces the part collides with.

    ``decomposition="coacd"``: CoACD (threshold ``COACD_THRESHOLD``, at most ``COACD_MAX_PIECES`` (-1: any number),
    ``seed``), cached under :func:`cache_dir` by a sha256 of the mesh geometry and the settings;
    ``"hull"``: the convex hull (no cache needed)."""
    if decomposition not in DECOMPOSITIONS:
        raise InputError(f"decomposition {decomposition!r}: expected one of {', '.join(DECOMPOSITIONS)}")
    if decomposition == "hull":
        return [np.asarray(mesh.convex_hull.vertices, dtype=np.float64)]
    key = _mesh_key(mesh, f"coacd/{COACD_THRESHOLD}/{COACD_MAX_PIECES}/{int(seed)}")
    path = cache_dir() / "coacd" / f"{key}.npz"
    if cache:
        cached = _cached_pieces(path)
        if cached is not None:
            return cached
    import coacd

    coacd.set_log_level("error")
    parts = coacd.run_coacd(coacd.Mesh(np.asarray(mesh.vertices, dtype=np.float64), np.asarray(mesh.faces, dtype=np.int32)),
                            threshold=COACD_THRESHOLD, max_convex_hull=COACD_MAX_PIECES, seed=int(seed))
    pieces = [np.asarray(v, dtype=np.float64) for v, _ in parts if len(v) >= 4]
    if not pieces:
        pieces = [np.asarray(mesh.convex_hull.vertices, dtype=np.float64)]
    if cache:
        off = np.cumsum([0] + [len(p) for p in pieces])
        buf = io.BytesIO()
        np.savez(buf, vertices=np.concatenate(pieces), offsets=off)
        try:
            write_atomic_bytes(path, buf.getvalue())
        except InputError as exc:  # a read-only cache folder costs the next run time, not this run's result
            warnings.warn(f"CoACD cache not written ({exc}); set $GRASPLAN_CACHE_DIR to a writable folder", stacklevel=2)
    return pieces


#: a cache entry larger than this is not one grasplan wrote
MAX_CACHE_BYTES = 200_000_000


def _cached_pieces(path: Path) -> list[np.ndarray] | None:
    """The convex pieces stored in the cache entry ``path``; None when there is none or it is
    damaged, truncated or not an entry grasplan wrote (the caller then recomputes and replaces it)."""
    import zipfile

    if not path.is_file():
        return None
    try:
        data = read_input_bytes(path, what="CoACD cache entry", max_bytes=MAX_CACHE_BYTES)
        with np.load(io.BytesIO(data), allow_pickle=False) as z:
            v = np.asarray(z["vertices"], dtype=np.float64)
            off = np.asarray(z["offsets"], dtype=np.int64)
    except (InputError, OSError, ValueError, KeyError, TypeError, EOFError, zipfile.BadZipFile):
        return None
    if (v.ndim != 2 or v.shape[1:] != (3,) or not np.isfinite(v).all() or off.ndim != 1 or len(off) < 2
            or off[0] != 0 or off[-1] != len(v) or np.any(np.diff(off) < 4)):
        return None
    return [v[a:b] for a, b in itertools.pairwise(off)]
