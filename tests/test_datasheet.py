"""dj.datasheet: the vendor-style table of one design with its drive, and the IRB 360 band."""

import math

import numpy as np
import pytest

import deltajax as dj
import sys

from deltajax.constraints import cycle_rate
from deltajax.datasheet import ROW_FIELDS, DatasheetError

#: toy sizes: a coarse volume grid and polar grid, few cycle samples (the numbers are checked against the same
#: functions at the same sizes, or against a band far wider than the grid error)
TOY = dict(volume_h=0.05, cylinder_grid=(9, 3, 9), n_samples=41)

# Published ABB IRB 360 FlexPicker cycle rates on the 25/305/25 mm cycle (figures include 2 x 35 ms vacuum delay
# and a 90 deg tool rotation): IRB 360-8/1130 160 / 140 / 100 picks/min at 1 / 4 / 8 kg (product specification);
# the light variants are quoted at about 200 picks/min at 0.1 kg (IRB 360-1/1130, a 0.30 s cycle; from ABB's
# product range, to be re-checked against the current product specification).
IRB360_PPM = {0.1: 200.0, 1.0: 160.0}
#: the band: our ``industrial`` estimate (masses are engineering guesses, no tool rotation, a 750 W servo whose
#: thermal rating binds) must lie within 25 % of the published figure
BAND_RTOL = 0.25


@pytest.fixture(scope="module")
def industrial_sheet():
    return dj.datasheet(dj.presets.industrial(), dj.presets.servo_750w(), dj.presets.INDUSTRIAL_GEAR_RATIO,
                        payloads=(0.0, 0.1, 1.0, 3.0), name="industrial", **TOY)


@pytest.mark.slow
def test_industrial_in_irb360_band(industrial_sheet):
    ds = industrial_sheet
    vendor = dict(zip(ds.payload, ds.picks_per_min_vendor))
    for payload, published in IRB360_PPM.items():
        assert abs(vendor[payload] - published) <= BAND_RTOL * published, (payload, vendor[payload], published)
    # the curve falls with payload (both columns), and the dwell costs picks
    assert np.all(np.diff(ds.picks_per_min[:-1]) < 0) and np.all(np.diff(ds.picks_per_min_vendor[:-1]) < 0)
    assert np.all(ds.picks_per_min_vendor[:-1] < ds.picks_per_min[:-1])
    # one limit binds at T_min: peak or RMS utilisation is 1
    binding = np.maximum(ds.peak_utilisation, ds.rms_utilisation)
    np.testing.assert_allclose(binding[:-1], 1.0, atol=1e-6)


@pytest.mark.slow
def test_datasheet_rows_match_cycle_rate(industrial_sheet):
    """The table is cycle_rate at the stated centre, not a second model; max_payload is the feasibility edge."""
    ds = industrial_sheet
    robot, motor, n = dj.presets.industrial(), dj.presets.servo_750w(), ds.gear_ratio
    cycle = dj.trajectory.adept_cycle(ds.centre, n_samples=TOY["n_samples"])
    r = cycle_rate(robot, cycle, motor, n, dwell=ds.dwell, payload_mass=1.0)   # eager: not the datasheet's jit
    k = list(ds.payload).index(1.0)
    assert math.isclose(ds.picks_per_min_vendor[k], float(r.picks_per_min), rel_tol=1e-12)
    assert ds.payload[-1] == ds.max_payload > 3.0
    rate = sys.modules["deltajax.datasheet"]._rate                               # compiled once for the sheet
    edge = lambda m: float(rate(robot, cycle, motor, n, 0.0, m).cycle_time)  # noqa: E731
    assert math.isfinite(edge(ds.max_payload)) and math.isinf(edge(ds.max_payload * 1.001))
    # working range: a cylinder of the requested H/D, centred cycle in its middle, inside the reachable volume
    assert math.isclose(ds.working_height, 0.25 * ds.working_diameter, rel_tol=1e-12)
    assert 0 < ds.working_volume < ds.reachable_volume
    assert math.isclose(ds.centre[2], ds.working_z_top + ds.working_height / 2, rel_tol=1e-12)
    assert ds.rows()[k]["payload"] == 1.0 and set(ds.rows()[k]) == {f for f, _, _ in ROW_FIELDS}
    assert ds.arm_peak_torque == pytest.approx(20.0 * 0.9 * 7.16)


@pytest.mark.parametrize("kw, field", [({"gear_ratio": 0.0}, "gear_ratio"), ({"vendor_dwell": -0.01}, "vendor_dwell"),
                                       ({"payloads": (0.1, -1.0)}, "payloads"), ({"hd_ratio": float("nan")}, "hd_ratio"),
                                       ({"centre": (0.0, 0.0, float("nan"))}, "centre"),
                                       ({"cylinder_grid": (9, 1, 9)}, "cylinder_grid")])
def test_bad_input_names_the_field(kw, field):
    args = dict(robot=dj.presets.industrial(), motor=dj.presets.servo_750w(), gear_ratio=20.0)
    args.update(kw)
    with pytest.raises(DatasheetError, match=field):
        dj.datasheet(args.pop("robot"), args.pop("motor"), args.pop("gear_ratio"), **args)


def test_no_mass_model_is_refused():
    with pytest.raises(DatasheetError, match="mass"):
        dj.datasheet(dj.presets.franco2026(fixed_R=0.2), dj.presets.servo_750w(), 20.0, **TOY)
