"""A design's good test at any base radius R: the one place that says what the designer's good test of a fixed or
reconfigurable design is. Every consumer (the designer's evaluator and its ray searches, the certify stage, the
R(t) operating mode, the run report's workspace figure) builds it here::

    gt = design_good_test(design, pb.good, pb.links.plate_overhang)
    gt.point(R, p)      # deltajax.constraints.good_point of the robot at base radius R (a PointCheck)
    gt.good(R, p)       # its flag
    gt.possible(R, p)   # its cheap necessary condition (good_point_possible)
    gt.decided(R, p)    # (flag, decided): good_point_decided, the flag wherever decided
    gt.decided_settle   # the same, handing its configuration to the full test (rays.settle_good)

The robot at R is :meth:`deltajax.ReconfigurableDelta.at` (a fixed design: :meth:`deltajax.Delta.
with_base_radius`), its R samples the design's (a fixed design: its own R) and the base plate's radius the largest R
plus the plate's overhang (a reconfigurable design's plate is built for R_max at every R). Pure and traceable.
"""

from __future__ import annotations

from typing import Any, NamedTuple

from .. import constraints as C
from ..geometry import ReconfigurableDelta
from .rays import Decided

__all__ = ["DesignGoodTest", "design_good_test"]


class DesignGoodTest(NamedTuple):
    """The good test of ``design`` (a :class:`deltajax.Delta` or :class:`deltajax.ReconfigurableDelta`) by ``spec``
    (:class:`deltajax.constraints.GoodSpec`) with the base plate of radius ``plate`` (m), at any base radius R."""

    design: Any
    spec: C.GoodSpec
    plate: Any

    @property
    def reconfigurable(self) -> bool:
        return isinstance(self.design, ReconfigurableDelta)

    def at(self, R):
        """The robot at base radius ``R`` (R frozen)."""
        return self.design.at(R) if self.reconfigurable else self.design.with_base_radius(R)

    def R_samples(self):
        """The design's R samples ((1,): a fixed design's own R)."""
        return self.design.R_samples() if self.reconfigurable else self.design.base_radius[None]

    def point(self, R, p) -> C.PointCheck:
        return C.good_point(self.at(R), p, self.spec, plate_radius=self.plate)

    def good(self, R, p):
        return self.point(R, p).good

    def possible(self, R, p):
        return C.good_point_possible(self.at(R), p, self.spec, plate_radius=self.plate)

    def decided(self, R, p):
        return C.good_point_decided(self.at(R), p, self.spec, plate_radius=self.plate)

    def decided_state(self, R, p):
        return C.good_point_decided(self.at(R), p, self.spec, plate_radius=self.plate, state=True)

    def settle(self, state: C.GoodState):
        return C.good_point_settle(state, self.spec)

    @property
    def decided_settle(self) -> Decided:
        """The decided test that hands its configuration to the full test where it leaves a pair undecided
        (:func:`deltajax.optimize.rays.settle_good`): the same answers, the IK solved once per pair."""
        return Decided(self.decided_state, self.settle)


def design_good_test(design, spec: C.GoodSpec, plate_overhang) -> DesignGoodTest:
    """``design``'s good test by ``spec``, its base plate the largest R plus ``plate_overhang`` (m)."""
    top = design.R_max if isinstance(design, ReconfigurableDelta) else design.base_radius
    return DesignGoodTest(design, spec, top + plate_overhang)
