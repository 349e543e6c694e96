"""experiment=datasheet: the table in results.h5 (units on every column) is dj.datasheet's, and its settings are
checked before anything compiles."""

import struct

import numpy as np
import pytest

import deltajax as dj
from deltajax.config import ConfigError
from deltajax.io import load


@pytest.mark.slow
def test_datasheet_job_table_has_units_and_the_library_numbers(toy_run):
    path = toy_run("datasheet")
    data = load(path)
    g = data["datasheet"]["industrial"]
    np.testing.assert_array_equal(g["payload"][:-1], [0.0, 0.1, 1.0])
    assert g["payload"][-1] == pytest.approx(float(g["max_payload"]))
    assert np.all(np.diff(g["picks_per_min"][:-1]) < 0)
    ds = dj.datasheet(dj.presets.industrial(), dj.presets.servo_750w(), 20.0, payloads=(0.0, 0.1, 1.0),
                      volume_h=0.05, cylinder_grid=(9, 3, 9), n_samples=41)
    np.testing.assert_allclose(g["picks_per_min_vendor"], ds.picks_per_min_vendor, rtol=1e-9)
    assert float(g["working_diameter"]) == pytest.approx(ds.working_diameter, rel=1e-9)
    import h5py
    with h5py.File(path, "r") as f:
        grp = f["datasheet/industrial"]
        for name in ("payload", "picks_per_min", "picks_per_min_vendor", "cycle_time", "peak_acceleration_g",
                     "working_diameter", "reachable_volume", "motor_peak_torque", "gear_ratio"):
            assert "units" in grp[name].attrs, name
        unit = lambda n: grp[n].attrs["units"].decode() if isinstance(grp[n].attrs["units"], bytes) else grp[n].attrs["units"]  # noqa: E731
        assert (unit("picks_per_min"), unit("payload"), unit("working_volume")) == ("1/min", "kg", "m^3")


@pytest.mark.parametrize("overrides, match", [
    (["source=nosuchthing"], "source='nosuchthing' is neither a preset"),
    (["experiment.motor.efficiency=1.5"], "experiment.motor.efficiency must be in"),
    (["experiment.payloads=[0.1,-2.0]"], r"experiment.payloads\[1\]"),
    (["experiment.gear_ratio=0"], "experiment.gear_ratio"),
])
def test_datasheet_settings_fail_in_one_line(tmp_path, overrides, match):
    from deltajax.run import run_experiment

    with pytest.raises(ConfigError, match=match) as err:
        run_experiment("datasheet", overrides, run_dir=tmp_path / "run")
    assert "\n" not in str(err.value)
    assert not (tmp_path / "run" / "results.h5").exists()


def test_source_is_refused_by_other_experiments(tmp_path):
    from deltajax.run import run_experiment

    with pytest.raises(ConfigError, match="source='industrial' is read only by experiment=datasheet"):
        run_experiment("dynamics_cycle", ["+source=industrial"], run_dir=tmp_path / "run")


@pytest.mark.slow
def test_datasheet_of_a_ga_run_uses_its_designs_and_drive(toy_run, tmp_path):
    """source=<ga_reconfig run dir>: the baseline and the recommended design, each with the run's motor and the
    design's own gear ratio (a design variable of the GA)."""
    from deltajax.run import run_experiment
    from toy_jobs import TOY

    ga = load(toy_run("ga_reconfig"))
    run_dir = tmp_path / "ds"
    extra = [a for a in TOY["datasheet"] if not a.startswith("source=")]
    run_experiment("datasheet", [f"source={toy_run('ga_reconfig').parent}", *extra], run_dir=run_dir)
    data = load(run_dir / "results.h5")
    S = ga["summary"]
    names = list(S["parameter_name"])
    k = names.index("gear_ratio")
    for col in ("baseline", "recommended"):
        g = data["datasheet"][col]
        assert float(g["gear_ratio"]) == pytest.approx(float(S[f"{col}_params"][k]), rel=1e-12)
        assert np.all(np.isfinite(g["picks_per_min"])) and float(g["working_volume"]) > 0
    png = (run_dir / "datasheet_recommended.png").read_bytes()
    # an A4 portrait page (8.27 x 11.69 in) at the runs' 120 dpi, not cropped to what is drawn on it
    assert png[:4] == b"\x89PNG" and struct.unpack(">II", png[16:24]) == (992, 1402)
