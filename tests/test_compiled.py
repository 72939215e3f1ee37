"""The compiled kernels (:mod:`grasplan.compiled`): the ahead-of-time build gives the same numbers as
numba's JIT from the same definition, runs only on arguments of exactly its types (anything else
goes to numba, never to machine code that would misread it), and is not used when it was built for
other sources, another NumPy, or is turned off. The whole warm-up and a plan that then imports no
numba are in tests/test_startup.py."""
from __future__ import annotations

import json

import numpy as np
import pytest

from grasplan.compiled import aot
from grasplan.compiled.jit import Kernel, kernel
from grasplan.grasps import quality_kernels, ranking


def _rotations(rng: np.random.Generator, n: int) -> np.ndarray:
    """(n, 3, 3) rotations of random unit quaternions, C-contiguous."""
    q = rng.normal(size=(n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    w, x, y, z = q.T
    R = np.stack([np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
                  np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
                  np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1)], 1)
    return np.ascontiguousarray(R)


def _margin_args(rng: np.random.Generator, M: int = 40, D: int = 6) -> tuple:
    """Arguments of ``margin_of_loads``: M grasps' TCP axes and origins, a centre of mass, D loads
    (N), per-grasp pad arms, widths and torsion lengths, then the scalars."""
    one = [np.abs(rng.normal(size=M)) * 0.01 + 0.001 for _ in range(5)]
    return (_rotations(rng, M), rng.normal(size=(M, 3)) * 0.01, rng.normal(size=3) * 0.01,
            rng.normal(size=(D, 3)) * 10.0, *one, 70.0, 0.3, 1e-3, -4.0, 3.0, 20)


def _distinct_args(rng: np.random.Generator, n: int = 300) -> tuple:
    p = rng.uniform(-0.05, 0.05, size=(n, 3))
    return (p, _rotations(rng, n), 0.01, float(np.cos(np.radians(20))), 0.01)


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    """Two real kernels (one calling another kernel) compiled ahead of time into a fresh folder,
    for the signatures numba compiles on these arguments."""
    rng = np.random.default_rng(0)
    found = []
    for k, args in ((quality_kernels.margin_of_loads, _margin_args(rng)), (ranking.greedy_distinct, _distinct_args(rng))):
        k.jit()(*args)
        found.append((k.name, k.py_func, k.jit().nopython_signatures))
    where = tmp_path_factory.mktemp("kernels")
    n, variants, path = aot.build(found, where)
    assert (n, variants) == (2, 2) and path.is_file()
    return where


def test_ahead_of_time_gives_numbas_numbers(built):
    loaded = aot.load(built)
    assert set(loaded) == {quality_kernels.margin_of_loads.name, ranking.greedy_distinct.name}
    rng = np.random.default_rng(1)
    for k, make in ((quality_kernels.margin_of_loads, _margin_args), (ranking.greedy_distinct, _distinct_args)):
        for _ in range(3):
            args = make(rng)
            (variant,) = loaded[k.name]
            assert variant.accepts(args)
            got, want = variant.function(*args), k.jit()(*args)
            assert got.dtype == want.dtype and np.array_equal(got, want), k.name
            assert np.any(got), "the comparison saw real work"


def test_a_kernel_runs_the_ahead_of_time_variant_only_on_its_own_types(built, monkeypatch):
    """A float32 array, a Fortran-ordered array or a bool where an int goes: numba's JIT runs (the
    compiled variant would misread the memory), with the JIT's result."""
    (variant,) = aot.load(built)[ranking.greedy_distinct.name]
    calls: list[int] = []

    def counting(*args):
        calls.append(1)
        return variant.function(*args)

    k = ranking.greedy_distinct
    monkeypatch.setattr(k, "_aot", ((variant.accepts, counting),))
    p, R, d, c, cell = _distinct_args(np.random.default_rng(2))
    want = k.jit()(p, R, d, c, cell)
    assert np.array_equal(k(p, R, d, c, cell), want) and len(calls) == 1
    for args in ((p.astype(np.float32), R, d, c, cell), (np.asfortranarray(p), R, d, c, cell),
                 (p, R, d, c, 1), (p[::2], R[::2], d, c, cell)):
        assert not variant.accepts(args)
        got = k(*args)
        assert np.array_equal(got, k.jit()(*args))
    assert len(calls) == 1, "every mismatched call went to numba"


def test_variant_checks_every_argument():
    C2 = ("array", np.dtype("<f8"), 2, "C", False)
    A1 = ("array", np.dtype("<i8"), 1, "A", False)
    R1 = ("array", np.dtype("<f8"), 1, "C", True)
    v = aot.Variant(lambda *a: None, (C2, A1, R1, ("int64", None, 0, "", False), ("float64", None, 0, "", False),
                                      ("bool", None, 0, "", False)))
    a, i, r = np.zeros((3, 2)), np.arange(6), np.zeros(4)
    ro = np.zeros(4)
    ro.flags.writeable = False
    assert v.accepts((a, i, r, 3, 1.5, True)) and v.accepts((a, i[::2], ro, np.int64(3), np.float64(1.5), np.bool_(1)))
    bad = [(a.T, i, r, 3, 1.5, True), (a[None], i, r, 3, 1.5, True), (a, i.astype(np.int32), r, 3, 1.5, True),
           (a, i, r, True, 1.5, True), (a, i, r, 3, 2, True), (a, i, r, 3, 1.5, 1), (a, i, r, 3.0, 1.5, True),
           (a.tolist(), i, r, 3, 1.5, True), (a, i, r, 3, 1.5), (a.astype(">f8"), i, r, 3, 1.5, True)]
    for args in bad:
        assert not v.accepts(args), args
    ro2 = np.zeros((3, 2))
    ro2.flags.writeable = False
    assert not v.accepts((ro2, i, r, 3, 1.5, True)), "a read-only array where the kernel may write"


def test_a_stale_or_foreign_build_is_not_used(built, monkeypatch, tmp_path):
    manifest = json.loads((built / aot.MANIFEST).read_text())
    for key, value, why in (("sources", {**manifest["sources"], quality_kernels.__name__: "0" * 64}, "changed since"),
                            ("numpy", "1.0.0", "built for numpy"), ("format", 0, "manifest format"),
                            ("cpu", "0123456789abcdef", "another CPU")):
        folder = tmp_path / key
        folder.mkdir()
        (folder / manifest["file"]).symlink_to(built / manifest["file"])
        (folder / aot.MANIFEST).write_text(json.dumps({**manifest, key: value}))
        assert aot.load(folder) == {}
        assert why in aot.status() and "warmup" in aot.status()
    assert aot.load(tmp_path / "nowhere") == {} and "no ahead-of-time kernels" in aot.status()
    for n, damaged in enumerate(([1, 2], {**manifest, "kernels": {"x": [["k999", []]]}},
                                 {**manifest, "kernels": {"x": [["k0", [["tensor", None, 0, "", False]]]]}},
                                 {**manifest, "file": "missing.so"}, {k: v for k, v in manifest.items() if k != "module"})):
        folder = tmp_path / f"damaged{n}"
        folder.mkdir()
        (folder / manifest["file"]).symlink_to(built / manifest["file"])
        (folder / aot.MANIFEST).write_text(json.dumps(damaged))
        assert aot.load(folder) == {} and "could not be loaded" in aot.status(), damaged
    assert manifest["cpu"] in (aot.GENERIC, aot.cpu_id())
    (tmp_path / "generic").mkdir()
    (tmp_path / "generic" / manifest["file"]).symlink_to(built / manifest["file"])
    (tmp_path / "generic" / aot.MANIFEST).write_text(json.dumps({**manifest, "cpu": aot.GENERIC}))
    assert set(aot.load(tmp_path / "generic")) == set(manifest["kernels"])  # a generic build runs anywhere
    monkeypatch.setenv(aot.AOT_ENV, "0")
    assert aot.load(built) == {} and "turned off" in aot.status()


def test_a_kernel_inside_a_kernel_types_as_numbas_dispatcher():
    """A kernel calling another through its module global (numba sees the callee's dispatcher)."""
    @kernel()
    def inner(x):
        return x * 3.0

    glob = {"inner": inner, "np": np}
    exec("def outer(a):\n    s = 0.0\n    for v in a:\n        s += inner(v)\n    return s\n", glob)
    outer = Kernel(glob["outer"], {})
    assert outer(np.arange(4.0)) == 18.0 and outer.name.endswith("outer")
    assert outer(a=np.arange(3.0)) == 9.0  # keywords: numba's dispatcher
    assert "grasplan kernel" in repr(outer)
