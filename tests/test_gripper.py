"""Gripper YAML loading, the issue-3 geometry of the default gripper, jaws and their sweep."""
from __future__ import annotations

from dataclasses import dataclass, fields, replace
from typing import ClassVar

import numpy as np
import pytest
import yaml

from grasplan.errors import ConfigError
from grasplan.gripper.load import available_grippers, load_gripper
from grasplan.gripper.model import Box, MeshShape


def _span(shape):
    c = shape.corners()
    return c.min(axis=0), c.max(axis=0)


def _egp_c_40_shapes(g, openings):
    """The EGP-C 40's boxes (60 x 40 x 95 mm housing, 8 x 16 x 40 mm jaws, TCP 127 mm from the
    flange, fingertips 8 mm past the TCP) at each of ``openings``."""
    T = np.eye(4)
    T[2, 3] = 0.127
    np.testing.assert_allclose(g.T_flange_tcp, T, atol=1e-12)
    assert len(g.body) == 1 and isinstance(g.body[0], Box)
    lo, hi = _span(g.body[0])
    np.testing.assert_allclose(lo, [-0.030, -0.020, -0.127], atol=1e-12)
    np.testing.assert_allclose(hi, [0.030, 0.020, -0.032], atol=1e-12)
    for opening in openings:
        left, right = g.fingers(opening)
        llo, lhi = _span(left)
        rlo, rhi = _span(right)
        np.testing.assert_allclose(lhi[0], -opening / 2, atol=1e-12)  # inner faces
        np.testing.assert_allclose(rlo[0], opening / 2, atol=1e-12)
        np.testing.assert_allclose(rhi - rlo, [0.008, 0.016, 0.040], atol=1e-12)
        np.testing.assert_allclose(lhi - llo, [0.008, 0.016, 0.040], atol=1e-12)
        np.testing.assert_allclose([rlo[2], rhi[2]], [-0.032, 0.008], atol=1e-12)
        np.testing.assert_allclose([rlo[1], rhi[1]], [-0.008, 0.008], atol=1e-12)
    assert g.symmetric


def test_default_gripper_is_the_egp_c_40_with_its_stroke():
    """The default: the EGP-C 40 moving each jaw 6 mm, fingers for the demo bracket's 30-42 mm."""
    g = load_gripper()
    assert g.name == "schunk_egp_c_40"
    assert (g.max_opening, g.stroke, g.min_opening) == pytest.approx((0.042, 0.012, 0.030))
    assert g.grip_force == 140 and g.mass == pytest.approx(0.34)
    _egp_c_40_shapes(g, (0.030, 0.036, 0.042))


def test_long_stroke_50_is_the_papers_model_with_the_same_boxes():
    """long_stroke_50: the EGP-C 40's boxes with jaws that close fully from 50 mm (Vogt et al.)."""
    g = load_gripper("long_stroke_50")
    assert g.max_opening == pytest.approx(0.050) and g.stroke is None and g.min_opening == 0.0
    _egp_c_40_shapes(g, (0.0, 0.013, 0.05))
    d = load_gripper()
    for f in ("grip_force", "mass", "symmetric"):
        assert getattr(g, f) == getattr(d, f), f


def test_shallow_variant_is_the_same_hardware_grasping_nearer_the_fingertips():
    """long_stroke_50_shallow: every shape of long_stroke_50 in the flange frame, the TCP (the
    contacts) 4 mm further out, so the fingertips reach 4 mm past the contacts instead of 8 mm."""
    deep, shallow = load_gripper("long_stroke_50"), load_gripper("long_stroke_50_shallow")
    np.testing.assert_allclose(shallow.T_flange_tcp[2, 3] - deep.T_flange_tcp[2, 3], 0.004, atol=1e-12)

    def in_flange(g, shape):
        c = shape.corners()
        return c @ g.T_flange_tcp[:3, :3].T + g.T_flange_tcp[:3, 3]

    for a, b in zip(deep.body, shallow.body, strict=True):
        np.testing.assert_allclose(in_flange(shallow, b), in_flange(deep, a), atol=1e-12)
    for opening in (0.0, 0.021, 0.05):
        for a, b in zip(deep.fingers(opening), shallow.fingers(opening), strict=True):
            np.testing.assert_allclose(in_flange(shallow, b), in_flange(deep, a), atol=1e-12)
        assert _span(deep.fingers(opening)[1])[1][2] == pytest.approx(0.008)
        assert _span(shallow.fingers(opening)[1])[1][2] == pytest.approx(0.004)
    for f in ("max_opening", "grip_force", "mass", "stroke", "symmetric"):
        assert getattr(shallow, f) == getattr(deep, f), f
    np.testing.assert_allclose(shallow.com, deep.com)


def test_swept_jaws_are_union_of_end_placements():
    g = load_gripper()
    left, right = g.swept_fingers(0.04, 0.022)
    lo, hi = _span(right)
    np.testing.assert_allclose([lo[0], hi[0]], [0.011, 0.020 + 0.008], atol=1e-12)
    lo, hi = _span(left)
    np.testing.assert_allclose([lo[0], hi[0]], [-0.028, -0.011], atol=1e-12)
    # order of the two openings does not matter
    a = g.swept_fingers(0.022, 0.04)[1]
    np.testing.assert_allclose(a.corners(), right.corners(), atol=1e-15)


def test_pregrasp_and_close_openings():
    g = load_gripper("long_stroke_50")
    np.testing.assert_allclose(g.pregrasp_opening([0.01, 0.045, 0.05]), [0.02, 0.05, 0.05])
    np.testing.assert_allclose(g.close_to_opening([0.01, 0.0485, 0.05]), [0.012, 0.05, 0.05])


def test_mesh_gripper_loads_relative_paths_and_hull_sweep():
    assert "round_mesh_jaws" in available_grippers()
    g = load_gripper("round_mesh_jaws")
    assert any(isinstance(b, MeshShape) for b in g.body)
    assert isinstance(g.finger, MeshShape)
    left, right = g.swept_fingers(0.05, 0.03)
    assert right.vertices[:, 0].min() == pytest.approx(0.015)
    assert right.vertices[:, 0].max() == pytest.approx(0.025 + 0.010)
    assert left.vertices[:, 0].max() == pytest.approx(-0.015)
    # the body cylinder spans z from -0.140 to -0.050, radius 40 mm
    v = g.body[0].vertices
    assert v[:, 2].min() == pytest.approx(-0.140) and v[:, 2].max() == pytest.approx(-0.050)
    assert np.linalg.norm(v[:, :2], axis=1).max() == pytest.approx(0.040, rel=1e-6)


def test_unknown_gripper_lists_available():
    with pytest.raises(ConfigError, match="available: .*schunk_egp_c_40"):
        load_gripper("no_such_gripper")


def _write(tmp_path, data):
    p = tmp_path / "g.yaml"
    p.write_text(yaml.safe_dump(data))
    return p


BASE = {
    "max_opening": 0.05,
    "T_flange_tcp": {"xyz": [0, 0, 0.1], "rpy_deg": [0, 0, 0]},
    "body": [{"box": {"size": [0.06, 0.04, 0.05], "center": [0, 0, -0.06]}}],
    "fingers": {"box": {"size": [0.008, 0.016, 0.04], "center_z": -0.012}},
}


@pytest.mark.parametrize(
    "patch, field",
    [
        ({"max_opening": -1}, "max_opening"),
        ({"max_opening": "wide"}, "max_opening"),
        ({"T_flange_tcp": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 2, 0], [0, 0, 0, 1]]}, "T_flange_tcp"),
        ({"T_flange_tcp": {"xyz": [0, 0]}}, "T_flange_tcp.xyz"),
        ({"body": []}, "body"),
        ({"body": [{"box": {"size": [0.06, 0.04], "center": [0, 0, 0]}}]}, r"body\[0\].box.size"),
        ({"body": [{"box": {"size": [0.06, 0.04, 0.1]}}]}, r"body\[0\].box.center"),
        ({"body": [{"sphere": 1}]}, r"body\[0\]"),
        ({"body": [{"mesh": {"path": "missing.stl"}}]}, r"body\[0\].mesh.path"),
        ({"fingers": {"box": {"size": [0.008, 0.016, 0.04]}}}, "fingers.box.center_z"),
        ({"fingers": {"box": {"size": [0.008, -0.016, 0.04], "center_z": 0}}}, r"fingers.box.size\[1\]"),
        ({"colour": "red"}, "colour"),
    ],
)
def test_malformed_gripper_names_the_field(tmp_path, patch, field):
    data = {**BASE, **patch}
    with pytest.raises(ConfigError, match=field):
        load_gripper(_write(tmp_path, data))


def test_gripper_from_path_and_matrix_form(tmp_path):
    data = {**BASE, "T_flange_tcp": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0.1], [0, 0, 0, 1]]}
    g = load_gripper(_write(tmp_path, data))
    assert g.name == "g" and g.T_flange_tcp[2, 3] == pytest.approx(0.1)
    assert g.symmetric


def test_asymmetric_box_body_detected(tmp_path):
    data = {**BASE, "body": [{"box": {"size": [0.06, 0.04, 0.05], "center": [0.01, 0, -0.06]}}]}
    assert not load_gripper(_write(tmp_path, data)).symmetric


def test_config_numbers_are_read_alike_in_every_description():
    """Grippers, cells and robots share one YAML number reader: pi expressions, sign checks."""
    from grasplan.config.lookup import config_number, config_vector
    from grasplan.errors import ConfigError

    assert config_number("-pi/2", "q_home[1]") == pytest.approx(-np.pi / 2)
    assert config_vector([0.1, "pi/4", 2], "xyz").tolist() == pytest.approx([0.1, np.pi / 4, 2.0])
    for bad, kw, msg in [(True, {}, "expected a number"), ("__import__('os')", {}, "cannot read"),
                         (float("inf"), {}, "finite"), (0.0, {"positive": True}, "> 0"),
                         (-1e-3, {"nonneg": True}, ">= 0")]:
        with pytest.raises(ConfigError, match=msg):
            config_number(bad, "field", **kw)
    with pytest.raises(ConfigError, match="list of 3 numbers"):
        config_vector([1, 2], "size")


# -- gripper kinds ---------------------------------------------------------------------------
def test_default_kind_reads_and_writes_as_before(tmp_path):
    """``kind: parallel_jaw`` is the default: a file with it reads like one without, and the
    default kind's JSON names no kind (plan files stay byte-identical)."""
    from grasplan.gripper.load import gripper_from_json

    plain = load_gripper(_write(tmp_path, BASE))
    p = tmp_path / "explicit.yaml"
    p.write_text(yaml.safe_dump({**BASE, "kind": "parallel_jaw"}))
    explicit = load_gripper(p)
    assert explicit.to_json(definition=True) == {**plain.to_json(definition=True), "name": "explicit"}
    d = plain.to_json(definition=True)
    assert "kind" not in d and "kind" not in plain.to_json()
    again = gripper_from_json({**d, "kind": "parallel_jaw"})
    assert again.to_json(definition=True) == d == gripper_from_json(d).to_json(definition=True)


def test_unknown_kind_lists_the_registered_ones(tmp_path):
    from grasplan.gripper.load import gripper_from_json
    from grasplan.gripper.registry import KINDS

    with pytest.raises(ConfigError, match=r"g.yaml: unknown gripper kind 'robotiq_9f'; available: parallel_jaw.*kind"):
        load_gripper(_write(tmp_path, {**BASE, "kind": "robotiq_9f"}))
    d = load_gripper(_write(tmp_path, BASE)).to_json(definition=True)
    with pytest.raises(ConfigError, match=f"unknown gripper kind 'suction'; available: {', '.join(sorted(KINDS))}"):
        gripper_from_json({**d, "kind": "suction"})


def test_a_new_kind_is_one_registration(tmp_path):
    """A kind registered from outside the package (a subclass with one more YAML field) is built by
    load_gripper from its ``kind:`` and round-trips through its JSON."""
    from grasplan.gripper.load import gripper_from_json
    from grasplan.gripper import parallel_jaw
    from grasplan.gripper.model import Gripper
    from grasplan.gripper.registry import KINDS, GripperKind, register

    @dataclass(frozen=True, eq=False)
    class Padded(Gripper):
        kind: ClassVar[str] = "padded_jaw"
        pad: float = 0.0

        def to_json(self, *, definition=False):
            return {**super().to_json(definition=definition), "pad": self.pad}

    def from_yaml(data, *, base, name, source=""):
        rest = {k: v for k, v in data.items() if k not in ("kind", "pad")}
        g = parallel_jaw.from_yaml(rest, base=base, name=name, source=source)
        return Padded(**{f.name: getattr(g, f.name) for f in fields(g)}, pad=float(data["pad"]))

    def from_json(d, *, where):
        g = parallel_jaw.from_json(d, where=where)
        return Padded(**{f.name: getattr(g, f.name) for f in fields(g)}, pad=float(d["pad"]))

    with pytest.raises(ValueError, match="says kind 'parallel_jaw'"):
        register(GripperKind(name="padded_jaw", description="", model=Gripper, from_yaml=from_yaml, from_json=from_json))
    register(GripperKind(name="padded_jaw", description="test", model=Padded, from_yaml=from_yaml, from_json=from_json))
    try:
        g = load_gripper(_write(tmp_path, {**BASE, "kind": "padded_jaw", "pad": 0.002}))
        assert isinstance(g, Padded) and g.pad == 0.002 and g.max_opening == 0.05
        d = g.to_json(definition=True)
        assert d["kind"] == "padded_jaw"
        back = gripper_from_json(d)
        assert isinstance(back, Padded) and back.pad == 0.002
        assert back.to_json(definition=True) == replace(g, source="embedded").to_json(definition=True)
    finally:
        KINDS.pop("padded_jaw", None)


def test_every_shipped_gripper_travels_within_its_datasheet_stroke():
    """docs/grippers.md's table of shipped grippers lists each one; its opening column is the
    loaded gripper's, and no jaws travel further (max_opening - min_opening) than the maker's
    catalogued stroke in that table."""
    from pathlib import Path

    doc = (Path(__file__).resolve().parents[1] / "docs" / "grippers.md").read_text()
    rows = {}
    for line in doc.split("## The shipped grippers", 1)[1].split("\n\n", 2)[1].splitlines()[2:]:
        cells = [c.strip() for c in line.strip("|").split("|")]
        rows[cells[0].split()[0].strip("`")] = cells
    assert set(rows) == set(available_grippers())
    for name, cells in rows.items():
        g = load_gripper(name)
        lo, hi = (float(x) for x in cells[2].split(" - "))
        assert (g.min_opening, g.max_opening) == pytest.approx((lo, hi), abs=1e-9), name
        if cells[4].startswith("none"):
            continue
        assert g.max_opening - g.min_opening <= float(cells[4]) * 1e-3 + 1e-9, name


def test_box_sweeps_at_once_are_the_per_pair_sweeps():
    """``swept_boxes`` over many pairs gives, row by row, exactly the boxes ``swept_fingers`` gives
    one pair at a time (either order of the pair); a linkage's jaws have none (their arc)."""
    from grasplan.gripper.model import rz180

    g = load_gripper("long_stroke_50")
    rng = np.random.default_rng(3)
    a, b = rng.uniform(0.0, 0.05, 40), rng.uniform(0.0, 0.05, 40)
    ext, T = g.swept_boxes(a, b)
    for k in range(40):
        left, right = g.swept_fingers(a[k], b[k])
        assert np.array_equal(right.extents, ext[k]) and np.array_equal(right.T_tcp_box, T[k])
        assert np.array_equal(left.T_tcp_box, rz180() @ T[k]) and np.array_equal(left.extents, ext[k])
    lo = g.fingers(min(a[0], b[0]))[1].corners()[:, 0].min()
    hi = g.fingers(max(a[0], b[0]))[1].corners()[:, 0].max()
    assert np.isclose(ext[0, 0], hi - lo)  # the sweep spans both end placements of the jaw
    assert load_gripper("robotiq_2f_85").swept_boxes(a, b) is None
