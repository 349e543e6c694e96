"""Integrity of results files end to end: what a resume or a rerun of a finished run trusts is verified first.

Every dataset carries its checksum and the file's integrity record (HDF5 user block) covers every attribute and
every group's members (deltajax.io). Each fault below (a checkpoint value, a deleted checksum attribute, a root
bookkeeping attribute, a finished stage's dataset, a truncated or edited finished run, a failure between a
stage's last write and its mark) must end in one line naming the file, what is wrong and what to do, with
nothing in the run directory changed; nothing may be used or reported as complete silently.
"""

import errno
import json
import shutil

import h5py
import numpy as np
import pytest

import deltajax.io as dio
from deltajax.rundir import MANIFEST, CheckpointError
from deltajax.run import run_experiment

from toy_jobs import overrides

TOY = overrides("ga_reconfig")


# -- the file format: every kind of stored item is covered (fast, no job) -----------------------------------------
def _small(path):
    res = dio.ResultsFile(path, attrs={"experiment": "demo", "ga_reconfig_stages": "screen,ga", "flag": True,
                                       "levels": [1, 2, 3]})
    res.put_axis("g", "x", np.arange(3.0), units="m")
    res.put("g", "v", np.ones(3), units="1", dims=("x",))
    res.put("g/sub", "names", np.asarray(["a", "bb"], dtype=object), units="1")
    res.set_attrs("g/sub", generations_done=2)
    res.flush()
    return path


@pytest.mark.parametrize("edit, message", [
    (lambda f: f.attrs.__setitem__("ga_reconfig_stages", "screen,ga,plots"),
     r"/ \(root\): its attribute 'ga_reconfig_stages' does not match its checksum"),
    (lambda f: f["g/sub"].attrs.__setitem__("generations_done", 5),
     r"/g/sub: its attribute 'generations_done' does not match its checksum"),
    (lambda f: f.attrs.__delitem__("flag"), r"its attribute 'flag' was removed"),
    (lambda f: f["g/v"].attrs.__delitem__("checksum"), r"/g/v has no checksum"),
    (lambda f: f["g/v"].attrs.__setitem__("units", "mm"), r"/g: its dataset 'v' has attributes that do not match"),
    (lambda f: f["g/v"].__setitem__(0, 2.0), r"/g/v does not match its checksum"),
    (lambda f: f.__delitem__("g/sub/names"), r"/g/sub: its dataset 'names' was removed"),
    (lambda f: f.create_dataset("g/extra", data=[1.0]), r"/g/extra has no checksum"),
])
def test_every_edit_is_refused_by_a_verified_read(tmp_path, edit, message):
    path = _small(tmp_path / "r.h5")
    dio.verify_file(path)
    assert dio.load(path, verify=True)["g"]["sub"]["attrs"]["generations_done"] == 2
    with h5py.File(path, "r+") as f:
        edit(f)
    dio.read(path)  # an unverified read still opens it (to inspect it)
    with pytest.raises(dio.ChecksumError, match=message) as err:
        dio.verify_file(path)
    assert "\n" not in str(err.value) and str(path) in str(err.value)
    with pytest.raises(dio.ChecksumError):
        dio.load(path)  # the library's readers verify by default
    if "g/v" in message or "'v'" in message:
        with pytest.raises(dio.ChecksumError):
            dio.open_xarray(path, "g")


def test_a_file_without_an_integrity_record_is_refused(tmp_path):
    path = tmp_path / "plain.h5"
    with h5py.File(path, "w") as f:
        f.attrs["experiment"] = "demo"
        f.create_dataset("g/v", data=np.ones(3)).attrs["checksum"] = dio.checksum(np.ones(3))
    with pytest.raises(dio.ChecksumError, match="has no integrity record"):
        dio.verify_file(path)


def test_the_record_survives_many_groups_and_attributes_and_xarray_reads_the_file(tmp_path):
    """The user block is sized from what is staged; HDF5, xarray and the verified reader all read the file."""
    res = dio.ResultsFile(tmp_path / "r.h5", attrs={f"attribute_{i}": "x" * i for i in range(60)})
    for g in range(40):
        res.put(f"group_{g}/nested_{g}", "v", np.arange(3.0), units="1")
        res.set_attrs(f"group_{g}", **{f"a{i}": i for i in range(10)})
    res.flush()
    dio.verify_file(res.path)
    assert int(dio.open_xarray(res.path, "group_7/nested_7").v[2]) == 2


def _walked_record(path):
    """The integrity record computed by walking the file as written (every attribute read back from HDF5)."""
    from deltajax.io.integrity import integrity_record, stored_record

    with h5py.File(path, "r") as f:
        walked = json.loads(integrity_record(f)[len(dio.INTEGRITY_MAGIC):])["groups"]
        return walked, stored_record(f)


def test_the_writers_record_is_the_files_own_flush_after_flush(tmp_path):
    """The writer remembers each dataset's record entry by what it wrote (it does not read the attributes back
    on every flush): after flushes that change a dataset's data, its attributes, or only an attribute's type,
    and add groups, the stored record is the one computed by walking the file."""
    res = dio.ResultsFile(tmp_path / "r.h5", attrs={"experiment": "demo", "levels": [1, 2, 3], "none": None})
    res.put_axis("g", "x", np.arange(3.0), units="m")
    res.put("g", "v", np.ones(3), units="1", dims=("x",), attrs={"flag": True, "limits": [0.5, 2.0]})
    res.put("g/sub", "names", np.asarray(["a", "bb"], dtype=object), units="1", attrs={"source": "here"})
    res.set_attrs("h/only_attrs", note="a group with attributes and no dataset")
    steps = [lambda: None,
             lambda: res.put("g", "v", np.zeros(3), units="1", dims=("x",), attrs={"flag": True, "limits": [0.5, 2]}),
             lambda: res.put("g", "v", np.zeros(3), units="1", dims=("x",), attrs={"flag": 1, "limits": [0.5, 2]}),
             lambda: res.put("g", "v", np.zeros(3), units="m", dims=("x",), attrs={"flag": 1, "limits": [0.5, 3]}),
             lambda: res.put("g/sub/deeper", "w", np.arange(4), units="1", long_name="another level")]
    seen = []
    for step in steps:
        step()
        res.flush()
        walked, stored = _walked_record(res.path)
        assert stored == walked
        seen.append(stored["g"]["members"]["v"])
        assert dio.load(res.path)["g"]["v"].sum() == (3.0 if len(seen) == 1 else 0.0)
    assert len(set(seen[:4])) == 4        # data, an attribute's type, units and a value each change the entry
    assert stored["g/sub"]["members"]["deeper"] == "group" and "h/only_attrs" in stored


def test_load_groups_reads_the_groups_asked_for_as_load_does(tmp_path):
    res = dio.ResultsFile(tmp_path / "r.h5", attrs={"experiment": "demo"})
    res.put("a", "v", np.arange(3.0), units="m")
    res.put("a/b", "w", np.ones(2), units="1")
    res.put("c", "u", np.zeros(1), units="1")
    res.flush()
    whole = dio.load(res.path)
    some = dio.load_groups(res.path, ("a", "missing"))
    assert set(some) == {"a"}
    assert np.array_equal(some["a"]["v"], whole["a"]["v"])
    assert np.array_equal(some["a"]["b"]["w"], whole["a"]["b"]["w"])
    assert some["a"]["units"] == whole["a"]["units"] and some["a"]["units"]["v"] == "m"


def test_an_edited_shard_is_never_merged(tmp_path, monkeypatch):
    """The merge reads finished shards verified: an edited one would otherwise get fresh checksums in the merge."""
    from deltajax.sweeps import REDUCERS, ShardError, merge_shards
    from test_results_reader import _shard

    monkeypatch.setitem(REDUCERS, "toy_total", lambda data, attrs: ({"total": np.float64(data["v"].sum())}, {}))
    shards = [_shard(tmp_path / f"{k}.h5", k, 2, "toy_total") for k in (0, 1)]
    dio.verify_file(merge_shards(shards, tmp_path / "ok.h5"))
    with h5py.File(shards[1], "r+") as f:
        f["g/v"][0] = 100.0
    with pytest.raises(ShardError, match=r"1\.h5:/g/v does not match its checksum.*rerun that shard"):
        merge_shards(shards, tmp_path / "m.h5")
    assert not (tmp_path / "m.h5").exists()


# -- the main job: a checkpoint and the bookkeeping of a stopped run ------------------------------------------------
@pytest.fixture(scope="module")
def stopped_run(tmp_path_factory):
    """A toy ga_reconfig run stopped after generation 2 of 4 (as if killed): its checkpoint is in results.h5."""
    d = tmp_path_factory.mktemp("stopped") / "run"
    run_experiment("ga_reconfig", TOY + ["experiment.stop_after=2"], run_dir=d)
    return d


def _copy(run_dir, tmp_path):
    d = tmp_path / "run"
    shutil.copytree(run_dir, d)
    return d


def _refused(d, match, *extra):
    """A rerun into ``d`` is refused with one line matching ``match`` and ``fresh=true``; nothing there changes."""
    before = {p.name: p.read_bytes() for p in d.iterdir() if p.is_file() and p.name != ".deltajax.lock"}
    with pytest.raises(CheckpointError, match=match + ".*fresh=true") as err:
        run_experiment("ga_reconfig", TOY + list(extra), run_dir=d)
    assert "\n" not in str(err.value) and str(d / "results.h5") in str(err.value)
    assert {p.name: p.read_bytes() for p in d.iterdir() if p.is_file() and p.name != ".deltajax.lock"} == before
    return str(err.value)


def _leaf(f):
    """The GA state's best fitness (the leaf that equals the checkpoint's best fitness)."""
    best = float(np.min(f["ga/checkpoint/fitness"][()]))
    for name, d in f["ga/checkpoint/state"].items():
        if d.shape == () and np.isclose(float(d[()]), best):
            return f"ga/checkpoint/state/{name}"
    return "ga/checkpoint/state/leaf_001"


@pytest.mark.slow
@pytest.mark.parametrize("tamper", ["leaf_value", "leaf_checksum", "stages", "generations_done", "screen_data"])
def test_tampered_stopped_run_is_refused_on_resume(stopped_run, tmp_path, tamper):
    d = _copy(stopped_run, tmp_path)
    with h5py.File(d / "results.h5", "r+") as f:
        if tamper == "leaf_value":        # the GA state's best fitness x 10: evosax would keep the fake best
            name = _leaf(f)
            f[name][()] = f[name][()] * 10
            match = f"{name} does not match its checksum"
        elif tamper == "leaf_checksum":   # a checkpoint leaf without its checksum attribute
            del f["ga/checkpoint/state/leaf_001"].attrs["checksum"]
            match = "ga/checkpoint/state/leaf_001 has no checksum"
        elif tamper == "stages":          # one root attribute would drop the whole GA result
            f.attrs["ga_reconfig_stages"] = "screen,ga"
            match = r"/ \(root\): its attribute 'ga_reconfig_stages' does not match its checksum"
        elif tamper == "generations_done":
            f["ga/checkpoint"].attrs["generations_done"] = 3
            match = "ga/checkpoint: its attribute 'generations_done' does not match its checksum"
        else:                             # a finished stage's data, which a resume would re-stage and re-checksum
            v = f["screen/top_genes"][()]
            v[0, 0] = 0.5
            f["screen/top_genes"][()] = v
            match = "screen/top_genes does not match its checksum"
    _refused(d, "cannot resume: .*" + match)
    with pytest.raises(dio.ChecksumError):  # not laundered: the file still fails a verified read
        dio.verify_file(d / "results.h5")


@pytest.mark.slow
def test_library_reads_of_a_tampered_checkpoint_refuse_it(stopped_run, tmp_path):
    """The job's own reads (not only the run directory's claim) verify: the checkpoint loader and the re-staging
    of a resume never use or re-checksum edited data."""
    import types

    from deltajax.jobs.designer_state import GA_CHECKPOINT
    from deltajax.jobs.stages import Runner
    from deltajax.rundir import recorded, restage

    path = _copy(stopped_run, tmp_path) / "results.h5"
    ctx = types.SimpleNamespace(results=dio.ResultsFile(path), log=lambda line: None)
    checkpoint = Runner(ctx, "ga_reconfig", fingerprint=recorded(path, "ga_reconfig")[0]).checkpoint(
        "ga", **GA_CHECKPOINT)
    assert checkpoint.load()["generations_done"] == 2
    assert recorded(path, "ga_reconfig")[1] == ["screen"]
    with h5py.File(path, "r+") as f:
        f["ga/checkpoint"].attrs["generations_done"] = 3
    with pytest.raises(CheckpointError, match="'generations_done' does not match its checksum.*fresh=true"):
        checkpoint.load()
    with pytest.raises(dio.ChecksumError, match="generations_done"):
        recorded(path, "ga_reconfig")
    with pytest.raises(dio.ChecksumError, match="generations_done"):
        restage(dio.ResultsFile(tmp_path / "other.h5"), path)


# -- a finished run is re-verified before "nothing to do" -------------------------------------------------------
@pytest.mark.slow
@pytest.mark.parametrize("damage, match", [
    ("truncate", "cannot trust the finished run: .* is not a readable HDF5 file"),
    ("double_picks", "cannot trust the finished run: .*verify/picks_per_min does not match its checksum"),
    ("missing", "cannot trust the finished run: .* is missing although"),
])
def test_damaged_finished_run_is_refused_not_reported_complete(toy_run, tmp_path, damage, match):
    d = _copy(toy_run("ga_reconfig").parent, tmp_path)
    path = d / "results.h5"
    if damage == "truncate":
        data = path.read_bytes()
        path.write_bytes(data[: len(data) // 2])
    elif damage == "double_picks":
        with h5py.File(path, "r+") as f:
            f["verify/picks_per_min"][()] = f["verify/picks_per_min"][()] * 2
        with pytest.raises(dio.ChecksumError, match="verify/picks_per_min does not match its checksum"):
            dio.load(path)  # the library's reader verifies by default: no doubled values without a word
        assert dio.load(path, verify=False)["verify"]["picks_per_min"].size  # inspecting it stays possible
    else:
        path.unlink()
        with pytest.raises(CheckpointError, match=match + ".*fresh=true"):
            run_experiment("ga_reconfig", TOY, run_dir=d)
        return
    _refused(d, match)


def test_damaged_finished_workspace_grid_is_refused(toy_run, tmp_path):
    """The same check for every job (here workspace_grid, whose results.h5 is its chunk checkpoint)."""
    ref = toy_run("workspace_grid")
    d = tmp_path / "run"
    shutil.copytree(ref.parent, d)
    with h5py.File(d / "results.h5", "r+") as f:
        f["workspace"].attrs["planes_done"] = 1
    with pytest.raises(CheckpointError, match="cannot trust the finished run: .*'planes_done' does not match its "
                                              "checksum.*fresh=true"):
        run_experiment("workspace_grid", overrides("workspace_grid"), run_dir=d)


# -- figures are a stage like any other ---------------------------------------------------------------------------
@pytest.mark.slow
def test_plots_stage_is_marked_only_after_its_figures_are_on_disk(toy_run, tmp_path, monkeypatch):
    """A full disk while the figures are written (the last write of the plots stage): the stage is not marked,
    and the rerun draws them and only then calls the run complete."""
    full = toy_run("ga_reconfig")
    d = tmp_path / "run"
    d.mkdir()
    # the finished run up to its results stage, written legitimately (as a run killed before its plots)
    res = dio.ResultsFile(d / "results.h5")
    from deltajax.rundir import restage

    restage(res, full)
    stages = dio.load(full)["attrs"]["ga_reconfig_stages"].split(",")
    res.set_attrs(ga_reconfig_stages=",".join(stages[:stages.index("results") + 1]))
    res.flush()
    manifest = json.loads((full.parent / MANIFEST).read_text())
    manifest["status"] = "running"
    (d / MANIFEST).write_text(json.dumps(manifest))
    real = dio._write_all

    def full_at_png(fd, data):
        if bytes(data[:4]) == b"\x89PNG":
            raise OSError(errno.ENOSPC, "No space left on device")
        real(fd, data)

    monkeypatch.setattr(dio, "_write_all", full_at_png)
    with pytest.raises(dio.ResultsWriteError, match=r"\.png.*no space left on device"):
        run_experiment("ga_reconfig", TOY, run_dir=d)
    assert dio.load(d / "results.h5")["attrs"]["ga_reconfig_stages"].split(",")[-1] == "results"
    assert json.loads((d / MANIFEST).read_text())["status"] == "running"
    monkeypatch.setattr(dio, "_write_all", real)
    run_experiment("ga_reconfig", TOY, run_dir=d)
    assert sorted(p.name for p in d.glob("*.png")) == sorted(p.name for p in full.parent.glob("*.png"))
    assert list(d.glob("*.png"))
    assert dio.load(d / "results.h5")["attrs"]["ga_reconfig_stages"].endswith(",results,plots,export,report")
    assert json.loads((d / MANIFEST).read_text())["status"] == "complete"
