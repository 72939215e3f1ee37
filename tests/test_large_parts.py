"""Large parts: the candidate and pose stages bound their work, say what would run when they
refuse, and what they emit on a finely tessellated sphere is still right (every candidate and
every collision-free grasp checked against the sphere itself).

Speed and memory figures are in ``benchmarks/bench_large.py``; here only properties that can fail:
the bounds hold (and trip at the documented limits, set low by monkeypatching), and the results
inside the bounds stay correct.
"""
from __future__ import annotations

import re
import struct

import numpy as np
import pytest
from click.testing import CliRunner

from grasplan.grasps import pipeline as gg
from grasplan.grasps import patches
from grasplan.candidates import region_overlap
from grasplan.candidates import regions as rg
from grasplan.candidates.pipeline import CandidateParams, compute_candidates
from grasplan.cli import main
from grasplan.errors import InputError
from grasplan.grasps.pipeline import compute_grasps
from grasplan.part.mesh import MAX_TRIANGLES, part_from_arrays
from grasplan.config.params import GraspParams

from fuzz_cases import uv_sphere

MU, BETA_DEG, MAX_OPENING = 0.3, 2.0, 0.05
RADIUS = 0.02




def soup(m: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """``m`` random triangles, vertices ~ N(0, 10 mm), in metres (the fuzz suite's soups)."""
    v = np.random.default_rng(seed).normal(size=(3 * m, 3)) * 0.01
    return v, np.arange(3 * m).reshape(-1, 3)


def check_on_sphere(contacts: np.ndarray, normals: np.ndarray, faces: np.ndarray, V: np.ndarray, F: np.ndarray,
                    radius: float) -> None:
    """Independent checks of every antipodal pair on an inscribed sphere mesh: each contact inside
    its own triangle (barycentric, recomputed from the vertices) and so between the sphere and the
    deepest chord; the normals are those triangles' outward normals, anti-parallel within beta; the
    closing axis inside both friction cones; width within the opening."""
    tri = V[F[faces]]                                        # (n, 2, 3, 3)
    n = np.cross(tri[..., 1, :] - tri[..., 0, :], tri[..., 2, :] - tri[..., 0, :])
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    assert np.allclose(normals, n, atol=1e-9)
    assert (np.einsum("kij,kij->ki", n, tri.mean(axis=2)) > 0).all()          # outward
    for k in range(2):
        a, b, c = (tri[:, k, i] for i in range(3))
        p = contacts[:, k]
        nn = np.einsum("ij,ij->i", n[:, k], n[:, k])
        assert np.abs(np.einsum("ij,ij->i", p - a, n[:, k])).max() <= 1e-9  # in the face's plane
        bary = [np.einsum("ij,ij->i", np.cross(v - u, p - u), n[:, k]) / nn for u, v in ((a, b), (b, c), (c, a))]
        assert min(float(np.min(x)) for x in bary) >= -1e-9 * radius
    sag = radius - np.abs(np.einsum("kij,kij->ki", n, tri[:, :, 0])).min()   # deepest face plane
    r = np.linalg.norm(contacts, axis=2)
    assert (r <= radius + 1e-9).all() and (r >= radius - sag - 1e-9).all()
    assert (np.einsum("ki,ki->k", normals[:, 0], normals[:, 1]) <= -np.cos(np.radians(BETA_DEG)) + 1e-12).all()
    d = contacts[:, 1] - contacts[:, 0]
    w = np.linalg.norm(d, axis=1)
    assert (w > 0).all() and (w <= MAX_OPENING + 1e-12).all()
    dn = d / w[:, None]
    cosf = np.cos(np.arctan(MU)) - 1e-9
    assert (np.einsum("ij,ij->i", dn, -normals[:, 0]) >= cosf).all()
    assert (np.einsum("ij,ij->i", dn, normals[:, 1]) >= cosf).all()


@pytest.fixture(scope="module")
def sphere50k():
    v, f = uv_sphere(50_000)
    return part_from_arrays(v, f, units="m")


def _matched(want, got, *, dist: float, deg: float) -> float:
    """Share of the candidates ``want`` with one of ``got`` whose grasp centre is within ``dist`` and
    whose closing axis (sign-free) is within ``deg``."""
    def feat(c):
        a = c.contacts[:, 1] - c.contacts[:, 0]
        return c.contacts.mean(axis=1), a / np.linalg.norm(a, axis=1, keepdims=True)
    (mw, aw), (mg, ag) = feat(want), feat(got)
    near = np.linalg.norm(mw[:, None] - mg[None], axis=2) <= dist
    close = np.abs(aw @ ag.T) >= np.cos(np.radians(deg))
    return float((near & close).any(axis=1).mean())


def test_curved_sub_cell_pairs_are_thinned_before_their_overlaps(sphere50k, monkeypatch):
    """Over the budget, the sphere's sub-cell area pairs are thinned to a few per deduplication cell
    before any overlap is computed: far fewer outline rows reach the overlap stage, the note says
    so, every candidate is still right, and the deduplicated cells covered are (nearly) those of
    the exact search (within a cell's pitch and axis step)."""
    exact = compute_candidates(sphere50k, CandidateParams())
    assert exact.notes == ()
    rows: list[int] = []
    inner = region_overlap.inside_parts

    def counting(reg, *a):
        rows.append(len(reg))
        return inner(reg, *a)

    monkeypatch.setattr(rg, "inside_parts", counting)
    monkeypatch.setattr(rg, "CURVED_ROWS_BUDGET", 100_000)
    bounded = compute_candidates(sphere50k, CandidateParams())
    assert len(bounded.notes) == 1 and "CURVED_ROWS_BUDGET" in bounded.notes[0]
    assert 0 < sum(rows) <= 100_000, f"{sum(rows)} outline rows examined"
    c = bounded.candidates
    V, F = np.asarray(bounded.mesh.vertices), np.asarray(bounded.mesh.faces)
    check_on_sphere(c.contacts, c.normals, c.faces, V, F, RADIUS)
    share = _matched(exact.candidates, c, dist=0.002, deg=10.0)   # one deduplication cell
    assert share >= 0.95, f"{share:.1%} of the exact search's candidates have a match"


def test_sphere_grasps_every_ok_grasp_checked(sphere50k, monkeypatch):
    """A 50k-triangle sphere through the whole grasp stage with the large-part contact patches forced
    (slab cells, moments turned per roll): every candidate and every collision-free grasp is
    antipodal on the sphere (TCP at the contacts' midpoint, x along the closing axis), and the
    contact patches equal the exact per-roll clipping's."""
    monkeypatch.setattr(patches, "GRID_FACES", 0)
    res = compute_grasps(sphere50k, grasps=GraspParams(roll_step_deg=90))
    c = res.cand.candidates
    V, F = np.asarray(res.cand.mesh.vertices), np.asarray(res.cand.mesh.faces)
    check_on_sphere(c.contacts, c.normals, c.faces, V, F, RADIUS)
    ok = np.flatnonzero(res.status == "ok")
    assert len(ok) > 0
    T = res.frames.T_part_tcp[ok]
    k = res.frames.candidate[ok]
    check_on_sphere(c.contacts[k], c.normals[k], c.faces[k], V, F, RADIUS)
    assert np.allclose(T[:, :3, 3], c.contacts[k].mean(axis=1), atol=1e-12)
    axis = c.contacts[k, 1] - c.contacts[k, 0]
    assert np.allclose(T[:, :3, 0], axis / np.linalg.norm(axis, axis=1, keepdims=True), atol=1e-9)
    area, kind, widths = patches.contact_patches(sphere50k.mesh, res.gripper, T, c.contacts[k])
    monkeypatch.setattr(patches, "GRID_FACES", 10**12)
    area0, kind0, widths0 = patches.contact_patches(sphere50k.mesh, res.gripper, T, c.contacts[k])
    assert (area0 > 0).all()
    assert np.allclose(area, area0, rtol=1e-9, atol=0) and np.array_equal(kind, kind0)
    assert np.allclose(widths, widths0, rtol=1e-6, atol=1e-12)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_soup_samples_refused_with_the_spacing_that_runs(seed, monkeypatch):
    """A soup whose overlapping regions would give more samples than MAX_SAMPLES is refused before
    sampling; the message names the estimate, the limit and a --spacing, and that spacing runs
    within the limit."""
    v, f = soup(1500, seed)
    part = part_from_arrays(v, f, units="m")
    n_default = len(compute_candidates(part, CandidateParams()).candidates)
    limit = n_default // 3
    monkeypatch.setattr(rg, "MAX_SAMPLES", limit)
    with pytest.raises(InputError) as e:
        compute_candidates(part, CandidateParams())
    msg = str(e.value)
    assert f"{limit:,}" in msg and "MAX_SAMPLES" in msg and "<memory>" in msg
    m = re.search(r"use --spacing ([0-9.]+)mm", msg)
    assert m, msg
    res = compute_candidates(part, CandidateParams(spacing=float(m.group(1)) * 1e-3))
    assert 0 < len(res.candidates) <= limit


def test_soup_area_pairs_bounded(monkeypatch):
    """The streamed area pairs stop at MAX_AREA_PAIRS with a message naming the limit, the triangle
    count and the triangle count that would run; that many triangles of the same soup do run."""
    v, f = soup(6000)
    monkeypatch.setattr(rg, "MAX_AREA_PAIRS", 1000)
    with pytest.raises(InputError, match=r"more than 1,000 pairs of opposing surface areas .* 6,000 triangles.*"
                                         r"decimate it") as e:
        compute_candidates(part_from_arrays(v, f, units="m"), CandidateParams())
    m = re.search(r"to at most ([0-9,]+) triangles", str(e.value))
    assert m, str(e.value)
    n = int(m.group(1).replace(",", ""))
    assert 1000 <= n < 6000
    fewer = part_from_arrays(v[: 3 * n], f[:n], units="m")
    assert len(compute_candidates(fewer, CandidateParams(spacing=0.01)).candidates) > 0


def test_pose_count_capped_with_thinning(monkeypatch):
    """More candidates x rolls than MAX_POSES: the posed candidates are thinned to fit, the poses stay
    within the cap, the note names what was posed, and every posed candidate is one of the
    candidates (nothing invented)."""
    v, f = soup(2000)
    part = part_from_arrays(v, f, units="m")
    monkeypatch.setattr(gg, "MAX_POSES", 4000)
    res = compute_grasps(part, gripper="long_stroke_50", grasps=GraspParams(roll_step_deg=90))
    n = res.counts()
    assert n["candidates"] * 4 > 4000
    assert 0 < n["poses"] <= 4000
    notes = [w for w in res.quality_warnings() if "MAX_POSES" in w]
    assert len(notes) == 1 and f"posing {n['posed_candidates']:,} candidates" in notes[0] and "--thin" in notes[0]
    assert set(np.unique(res.frames.candidate)) <= set(range(n["candidates"]))


def _binary_stl(path, tri: np.ndarray) -> None:
    rec = np.zeros(len(tri), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")])
    rec["v"] = tri
    path.write_bytes(b"test_large_parts".ljust(80, b" ") + struct.pack("<I", len(tri)) + rec.tobytes())


def test_part_over_the_triangle_limit_refused_naming_what_runs(tmp_path):
    """A part of MAX_TRIANGLES + 1 triangles: exit 3, nothing written, one line naming the count, the
    limit and the decimation that would run."""
    n = MAX_TRIANGLES + 1
    v, f = uv_sphere(n)
    tri = v[f] * 1000.0
    tri = np.concatenate([tri, tri[: max(0, n - len(tri))]])[:n] if len(tri) < n else tri[:n]
    part = tmp_path / "big.stl"
    _binary_stl(part, tri)
    out = tmp_path / "c.json"
    r = CliRunner().invoke(main, ["candidates", str(part), "-o", str(out), "--units", "mm"])
    assert r.exit_code == 3, r.output
    assert not out.exists()
    err = [ln for ln in r.stderr.splitlines() if ln.startswith("grasplan: error:")]
    assert len(err) == 1 and "Traceback" not in r.output
    assert f"{n:,}" in err[0] and f"{MAX_TRIANGLES:,}" in err[0] and "decimate" in err[0]
