"""The one HDF5 reader (io.read) and its views, shard reducers looked up by name (old
"module:function" strings mapped, never imported), the sweeps CLI, and the chunk engine's results-file
checkpoint. All in-process and small (no CLI job runs here; tests/test_sweeps.py does those)."""

import ast
from pathlib import Path

import numpy as np
import pytest

import deltajax.io as dio
from deltajax.sweeps import LEGACY, REDUCERS, ShardError, get_reducer, merge_shards, register_reducer
from deltajax.workspace.chunks import reduce_plane_shards

REPO = Path(__file__).resolve().parent.parent


def test_io_imports_nothing_from_deltajax_outside_its_package():
    files = sorted((REPO / "deltajax" / "io").glob("*.py"))
    assert files
    for f in files:
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, ast.ImportFrom):  # ``from .integrity import ...`` stays inside deltajax.io
                assert node.level == 1 or (node.level == 0 and not (node.module or "").startswith("deltajax")), \
                    f"{f.name}: {ast.dump(node)}"
            elif isinstance(node, ast.Import):
                assert not any(a.name.startswith("deltajax") for a in node.names), f.name


def _toy_file(path):
    res = dio.ResultsFile(path, attrs={"experiment": "toy", "config": "a: 1\n"})
    res.put_axis("g", "x", np.array([0.0, 0.5, 1.0]), units="m")
    res.put_axis("g", "name", np.array(["a", "bc"], dtype=object), units="1")
    res.put("g", "v", np.arange(6.0).reshape(3, 2), units="N m", dims=("x", "name"), attrs={"description": "d"})
    res.put("g", "n", 7, units="1")
    res.put("g/sub", "w", np.array([1, 2], np.int32), units="1")
    res.set_attrs("g", h=0.5, label="toy")
    return res.flush(final=True)


def test_one_reader_keeps_dims_units_attributes_and_load_and_xarray_are_its_views(tmp_path):
    path = _toy_file(tmp_path / "r.h5")
    c = dio.read(path)
    v = c.variables["g"]["v"]
    assert v.dims == ("x", "name") and v.units == "N m" and not v.is_axis
    assert v.attrs["description"] == "d" and v.attrs["checksum"].startswith("sha256:")
    assert c.variables["g"]["x"].is_axis and list(c.variables["g"]["name"].data) == ["a", "bc"]
    assert c.group_attrs["g"] == {"h": 0.5, "label": "toy"} and c.attrs["experiment"] == "toy"
    assert c.variables["g/sub"]["w"].dims == ("w_dim0",)
    # views: the same arrays and attributes
    full = dio.load(path)
    np.testing.assert_array_equal(full["g"]["v"], v.data)
    assert full["g"]["units"]["v"] == "N m" and full["g"]["attrs"]["h"] == 0.5
    np.testing.assert_array_equal(full["g"]["sub"]["w"], [1, 2])
    assert dio.load(path, "g/sub")["units"] == {"w": "1", "w_dim0": "1"}
    ds = dio.open_xarray(path, "g")
    assert ds["v"].dims == ("x", "name") and ds["v"].attrs["units"] == "N m" and ds.attrs["label"] == "toy"
    np.testing.assert_array_equal(ds["x"].values, [0.0, 0.5, 1.0])
    # partial reads: only small datasets, or attributes only; checksums verified on request
    assert set(dio.read(path, max_elements=1).variables["g"]) == {"n"}
    assert dio.read(path, "g", max_elements=0).variables == {"g": {}, "g/sub": {}}
    dio.read(path, verify=True)
    import h5py

    with h5py.File(path, "r+") as f:
        f["g/v"][0, 0] = 99.0
    with pytest.raises(dio.ChecksumError, match="g/v does not match its checksum"):
        dio.read(path, "g", verify=True)
    with pytest.raises(dio.ResultsGroupError, match="no group 'nope'"):
        dio.read(path, "nope")


def test_reducers_are_looked_up_by_name_and_old_strings_are_mapped_not_imported():
    assert get_reducer("workspace_planes") is reduce_plane_shards
    for old in ("deltajax.jobs.workspace_grid:reduce_shards", "deltajax.experiments.workspace_grid:reduce_shards"):
        assert LEGACY[old] == "workspace_planes" and get_reducer(old) is reduce_plane_shards
    with pytest.raises(ShardError, match=r"'os:system' is not a registered reducer; registered: \[.*workspace_planes"):
        get_reducer("os:system")
    with pytest.raises(ValueError, match="without ':'"):
        register_reducer("a:b", len)
    with pytest.raises(ValueError, match="already registered"):
        register_reducer("workspace_planes", len)


def _shard(path, k, n, reduce):
    """Shard k of n of a toy sharded group: 'v' along axis 'x', 'total' recomputed by the reducer."""
    x = np.arange(4.0)[2 * k:2 * k + 2]
    res = dio.ResultsFile(path, attrs={"experiment": "toy", "config": f"shard: {k}\nn_shards: {n}\n"})
    res.put_axis("g", "x", x, units="m")
    res.put("g", "v", x ** 2, units="1", dims=("x",))
    res.put("g", "total", np.float64((x ** 2).sum()), units="1")
    res.set_attrs("g", shard_axis="x", shard=k, n_shards=n, shard_start=2 * k, shard_stop=2 * k + 2,
                  shard_reduce=reduce)
    return res.flush(final=True)


def test_merge_uses_the_registered_reducer_and_the_sweeps_cli(tmp_path, monkeypatch):
    def total(data, attrs):
        return {"total": np.float64(data["v"].sum())}, {"n_merged": len(attrs)}

    monkeypatch.setitem(REDUCERS, "toy_total", total)
    monkeypatch.setitem(LEGACY, "toy.module:total", "toy_total")  # an old-style string written by a file
    for reduce in ("toy_total", "toy.module:total"):
        d = tmp_path / reduce.replace(":", "_")
        d.mkdir()
        shards = [_shard(d / f"{k}.h5", k, 2, reduce) for k in (1, 0)]
        out = merge_shards(shards, d / "m.h5")
        m = dio.load(out, "g")
        np.testing.assert_array_equal(m["v"], np.arange(4.0) ** 2)
        assert m["total"] == 14.0 and m["attrs"]["n_merged"] == 2 and m["attrs"]["n_shards"] == 1
    bad = [_shard(tmp_path / f"b{k}.h5", k, 2, "unregistered") for k in (0, 1)]
    with pytest.raises(ShardError, match="'unregistered' is not a registered reducer"):
        merge_shards(bad, tmp_path / "bad.h5")
    from deltajax.sweeps.__main__ import main

    assert main([str(shards[0]), str(shards[1]), "-o", str(tmp_path / "cli.h5")]) == 0
    np.testing.assert_array_equal(dio.load(tmp_path / "cli.h5", "g")["v"], np.arange(4.0) ** 2)
    assert main([str(shards[0]), "-o", str(tmp_path / "x.h5")]) == 2  # one shard of two: refused, exit 2


