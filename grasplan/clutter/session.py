"""A clutter-removal run set up once and played round by round (``grasplan clutter`` and
``benchmarks/clutter.py`` share it): the setup, the parts, a warm :class:`grasplan.Picker` with each
part's grasp database at its density, and the protocol.

    run = ClutterRun(ClutterOptions(parts=(("TLess20.stl", 1, None),), protocol="pile"))
    rr = run.round(0)            # a RoundResult; round r drops with seed + r
    doc = run.report([rr])       # the grasplan.clutter/1 document
"""
from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from ..config.params import DEFAULT_ROBOT, PAPER_GRIPPER, GraspParams
from ..errors import InputError
from ..pick.params import PickParams
from ..sim.drop import DropParams
from .protocols import PROTOCOLS, protocol as protocol_named

if TYPE_CHECKING:
    from .rounds import RoundResult

#: the planner's options a clutter run passes on (the others are grasplan pick's defaults)
PICK_OPTIONS = ("lift_depth", "lift_contact", "lift_carry", "max_lift_tilt_deg", "min_gravity_margin")
#: a clutter run plans only grasps predicted to hold (grasplan pick's default is 0: off)
MIN_GRAVITY_MARGIN = 1.0


@dataclass(frozen=True)
class ClutterOptions:
    """What a clutter run is: ``parts`` ((mesh path, count per pile, material or None), ...), read
    in ``units``; the ``cell`` (name or path; it must have a bin), ``robot`` and ``gripper``;
    the ``protocol`` (:data:`grasplan.clutter.protocols.PROTOCOLS`); the pose error
    ``pose_noise`` ((m, deg)); ``max_occlusion``: parts an overhead camera sees at least this much
    of hidden are left out of the planner's scene (1: none); the physics ``drop``, the
    planner's options ``pick`` (:data:`PICK_OPTIONS` only) and ``push``: when no pick is planned,
    plan and execute a push (:mod:`grasplan.pick.push`)."""

    parts: tuple[tuple[str, int, str | None], ...]
    cell: str = "bin"
    units: str = "auto"
    protocol: str = "bin"
    pose_noise: tuple[float, float] = (0.0, 0.0)
    max_occlusion: float = 1.0
    robot: str = DEFAULT_ROBOT
    gripper: str = PAPER_GRIPPER
    drop: DropParams = field(default_factory=DropParams)
    pick: dict[str, Any] = field(default_factory=dict)
    push: bool = False

    def __post_init__(self) -> None:
        protocol_named(self.protocol)
        if not self.parts:
            raise InputError("clutter: give at least one --part PATH:COUNT")
        if not (0.0 < self.max_occlusion <= 1.0):
            raise InputError(f"--max-occlusion {self.max_occlusion!r}: expected a share in (0, 1], e.g. 0.8 "
                             f"(parts hidden 80 % or more are not planned); 1 plans every part")
        unknown = set(self.pick) - set(PICK_OPTIONS)
        if unknown:
            raise InputError(f"clutter: planner options {sorted(unknown)} are not passed on; valid: {PICK_OPTIONS}")


class ClutterRun:
    """A run's setup, loaded once (module docstring). ``setup``: a :class:`grasplan.setup.resolved.Setup`
    already built for the options' robot, gripper and cell (the CLI builds it first to guard its
    outputs); ``info`` / ``warn`` get progress lines and the parts' warnings."""

    def __init__(self, options: ClutterOptions, *, setup: Any = None, info: Callable[[str], None] | None = None,
                 warn: Callable[[str], None] | None = None):
        from ..pick import Picker
        from ..setup.resolved import build_setup
        from ..sim.drop import load_items
        from .perception import noise_reach
        from .world import pad_arc

        self.options = o = options
        self.protocol = PROTOCOLS[o.protocol]
        if setup is None:
            setup = build_setup(robot=o.robot, gripper=o.gripper, cell=o.cell)
        c, g, rob = setup.cell, setup.gripper, setup.robot
        assert c is not None and g is not None and rob is not None  # build_setup loads each one it is given
        if c.bin is None:
            raise InputError(f"--cell {o.cell}: the cell has no bin to drop parts into; use a cell with a bin "
                             f"(e.g. --cell bin; docs/cells.md)")
        pad_arc(g)  # a linkage the clutter world cannot model: refused now (exit 3), not after the first drop
        self.cell, self.gripper = c, g
        self.items = load_items(list(o.parts), units=o.units, info=info, warn=warn)
        # the planner refuses parts below their support by more than overlap_tol: pose noise moves them by up to this
        tol = PickParams.default("overlap_tol") + noise_reach([it.part for it in self.items], o.pose_noise)
        # the grasp databases ranked for the parts' simulated mass (the gravity margin and the score depend on it)
        self.picker = Picker(rob, gripper=g, cell=self.protocol.planner_cell(c),
                             params=PickParams(overlap_tol=min(tol, 0.05),
                                               **{"min_gravity_margin": MIN_GRAVITY_MARGIN, **o.pick}),
                             database=GraspParams(material=o.drop.material, density=o.drop.density))
        for it in self.items:  # each part's grasp database at the density it is dropped with
            material, density = it.physics(o.drop)
            self.picker.add_part(it.name, it.part, material=material, density=density)

    @property
    def parts_per_round(self) -> int:
        return sum(it.count for it in self.items)

    def round(self, r: int, *, record: bool = False, cold: bool = False,
              progress: Callable[[str], None] | None = None) -> RoundResult:
        """Round ``r`` (pile seed ``drop.seed + r``; :func:`grasplan.clutter.rounds.run_round`)."""
        from .rounds import run_round

        o = self.options
        return run_round(self.cell, self.items, self.gripper,
                         lambda s, skip=(): self.picker.plan(s, max_picks=1, push=o.push, push_skip=skip), r=r,
                         drop=o.drop, noise=o.pose_noise, cell_ref=o.cell, record=record, cold=cold,
                         protocol=self.protocol, max_occlusion=o.max_occlusion, progress=progress)

    def params_json(self, rounds: int) -> dict[str, Any]:
        """The report's ``params`` block."""
        from .execute import PROTOCOL
        from .pushing import PUSH_PROTOCOL

        o = self.options
        return {**o.drop.to_json(), "rounds": rounds, "protocol": self.protocol.name,
                "pose_noise_m": o.pose_noise[0], "pose_noise_deg": o.pose_noise[1],
                "pose_noise_model": "one error per part and round", "max_occlusion": o.max_occlusion, "push": o.push,
                "pick": self.picker.params.to_json(), "execution": PROTOCOL, "push_execution": PUSH_PROTOCOL,
                "pushes_in_gsr": False}

    def report(self, results: Sequence[RoundResult]) -> dict[str, Any]:
        """The ``grasplan.clutter/1`` document of these rounds."""
        from ..sim.drop import parts_record
        from .report import report_json

        return report_json(results, params=self.params_json(len(results)),
                           parts=parts_record(self.items, self.options.drop), cell=self.options.cell,
                           gripper=self.gripper.to_json(), robot=self.picker.robot.name)
