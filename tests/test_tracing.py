"""deltajax.tracing: a kernel traced once however many call sites and programs use it (same numbers as traced in
place), and programs kept across processes (exported, read back, bit-identical to the program traced in place,
keyed by their content and input shapes, a damaged entry rebuilt, off when there is no cache folder); the
designer's evaluators are read back without running the designer's Python."""

import os
import subprocess
import sys
import textwrap

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from deltajax import tracing as T

jax.config.update("jax_enable_x64", True)


def test_traced_once_runs_the_python_once_for_every_call_site_and_transform():
    calls = []

    def kernel(x, scale, *, mode="sum"):
        calls.append(mode)
        y = jnp.sin(x) * scale
        return jnp.sum(y) if mode == "sum" else jnp.max(y)

    shared = T.traced_once(kernel)

    def program(f):
        def g(x):
            a = f(x, 2.0)
            b = jax.vmap(lambda r: f(r, 2.0))(jnp.stack([x, 2 * x]))
            c = jax.grad(lambda r: f(r, 2.0))(x)
            return a + jnp.sum(b) + jnp.sum(c)
        return jax.jit(g)

    x = jnp.linspace(0.0, 1.0, 5)
    want = program(kernel)(x)
    n_inplace = len(calls)
    calls.clear()
    got = program(shared)(x)
    assert len(calls) == 1 < n_inplace          # one trace for the three call sites (vmap and grad transform it)
    assert float(got) == float(want)            # inlined: the same numbers as traced in place
    program(shared)(x + 1.0)                    # same structure: no new trace
    assert len(calls) == 1
    shared(x, 3.0)                              # another static value is another program
    shared(x, 2.0, mode="max")
    assert calls == ["sum", "sum", "max"]


@pytest.fixture()
def program_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("DELTAJAX_PROGRAM_CACHE", str(tmp_path))
    saved = dict(T._LOADED)
    T._LOADED.clear()
    yield tmp_path
    T._LOADED.clear()
    T._LOADED.update(saved)


def _fn(x, y):
    return {"s": jnp.cumsum(jnp.exp(-x) * y), "m": jnp.max(x)}


def test_persistent_exports_once_reads_back_and_gives_the_numbers_of_the_program_itself(program_cache):
    f = jax.jit(_fn)
    x, y = np.linspace(0, 3, 7), np.linspace(1, 2, 7)
    before = dict(T.STATS)
    p = T.persistent(f, "demo", "content-a")
    out = p(x, y)
    assert T.STATS["exported"] == before["exported"] + 1
    files = list((program_cache / "demo").glob("*.jaxexport"))
    assert len(files) == 1
    T._LOADED.clear()                                           # as a new process: read from disk
    again = T.persistent(f, "demo", "content-a")(x, y)
    assert T.STATS["loaded"] == before["loaded"] + 1
    want = f(x, y)
    for k in want:
        np.testing.assert_array_equal(np.asarray(out[k]), np.asarray(want[k]))
        np.testing.assert_array_equal(np.asarray(again[k]), np.asarray(want[k]))
    # another content or another input shape is another program
    T.persistent(f, "demo", "content-b")(x, y)
    T.persistent(f, "demo", "content-a")(x[:3], y[:3])
    assert len(list((program_cache / "demo").glob("*.jaxexport"))) == 3


def test_a_kept_program_runs_inside_a_transformation_of_its_caller(program_cache):
    # the caller jits around the kept program (the main job's resumed GA does): its inputs are tracers, which a
    # compiled executable does not take; the exported program's jitted call runs there, with the same numbers
    f = jax.jit(_fn)
    x, y = np.linspace(0, 3, 7), np.linspace(1, 2, 7)
    p = T.persistent(f, "demo", "k")
    want = np.asarray(p(x, y)["s"])
    T._LOADED.clear()                                           # a new process: the executable is read back
    before = dict(T.STATS)
    p = T.persistent(f, "demo", "k")
    np.testing.assert_array_equal(np.asarray(p(x, y)["s"]), want)
    assert T.STATS == {"exported": before["exported"], "loaded": before["loaded"] + 1}
    np.testing.assert_array_equal(np.asarray(jax.jit(lambda a: p(a, y)["s"])(x)), want)
    assert T.STATS["loaded"] == before["loaded"] + 2             # the exported program, read for the traced call
    np.testing.assert_array_equal(np.asarray(p(x, y)["s"]), want)   # and concrete calls still run the executable
    # vmap and grad around a kept program fail with JAX's error (the exported program has no batching rule and
    # no VJP), never with other numbers
    with pytest.raises(NotImplementedError, match="Batching rule"):
        jax.vmap(lambda a: p(a, y)["s"])(np.stack([x, x]))
    with pytest.raises(ValueError, match="No VJP"):
        jax.grad(lambda a: p(a, y)["s"].sum())(x)


def test_forget_drops_one_kinds_programs_and_keeps_the_others(program_cache, monkeypatch):
    monkeypatch.setattr(T, "PROGRAMS", {})
    x, y = np.linspace(0, 3, 7), np.linspace(1, 2, 7)
    built = []

    def build():
        built.append(1)
        return jax.jit(_fn)

    for kind in ("certified", "other"):
        T.shared_program(kind, None, None, ("k",), build, persist=True)(x, y)
    assert len(built) == 2 and {k[0] for k in T._LOADED} >= {"certified", "other"}
    assert T.forget("certified") == 2                      # its shared program and its exported twin
    assert {k[0] for k in T.PROGRAMS} == {"other"} and "certified" not in {k[0] for k in T._LOADED}
    T.shared_program("other", None, None, ("k",), build)     # still kept: not built again
    T.shared_program("certified", None, None, ("k",), build)  # dropped: built again when asked for
    assert len(built) == 3


def test_a_damaged_program_is_rebuilt_with_a_warning(program_cache):
    f = jax.jit(_fn)
    x = np.ones(3)
    T.persistent(f, "demo", "k")(x, x)
    paths = sorted((program_cache / "demo").glob("*"), key=lambda p: p.suffix)   # exported program, executable
    assert [p.suffix for p in paths] == [".jaxexport", ".xlaexec"]
    for p in paths:
        p.write_bytes(b"not a program")
    T._LOADED.clear()
    with pytest.warns(UserWarning, match="rebuilding the cached program") as caught:
        out = T.persistent(f, "demo", "k")(x, x)
    assert len(caught) == 2
    np.testing.assert_array_equal(np.asarray(out["s"]), np.asarray(f(x, x)["s"]))
    assert all(p.read_bytes() != b"not a program" for p in paths)


def test_the_kept_executable_runs_without_the_exported_program_and_a_damaged_one_is_compiled_again(program_cache):
    f = jax.jit(_fn)
    x, y = np.linspace(0, 3, 7), np.linspace(1, 2, 7)
    first = T.persistent(f, "demo", "k")(x, y)
    (exported,) = (program_cache / "demo").glob("*.jaxexport")
    (executable,) = (program_cache / "demo").glob("*.xlaexec")
    kept = exported.read_bytes()
    exported.unlink()                                           # only the executable is left
    T._LOADED.clear()                                           # as a new process
    before = dict(T.STATS)
    again = T.persistent(f, "demo", "k")(x, y)
    assert T.STATS == {"exported": before["exported"], "loaded": before["loaded"] + 1}
    assert not exported.exists()                                # run from the executable alone
    for k in first:
        np.testing.assert_array_equal(np.asarray(again[k]), np.asarray(first[k]))
    # a damaged executable is compiled again from the exported program, which is not traced again
    exported.write_bytes(kept)
    executable.write_bytes(b"damaged")
    T._LOADED.clear()
    before = dict(T.STATS)
    with pytest.warns(UserWarning, match="rebuilding the cached program"):
        out = T.persistent(f, "demo", "k")(x, y)
    assert T.STATS == {"exported": before["exported"], "loaded": before["loaded"] + 1}
    np.testing.assert_array_equal(np.asarray(out["s"]), np.asarray(first["s"]))
    assert executable.read_bytes() != b"damaged"
    T._LOADED.clear()                                           # and it runs in the next process
    np.testing.assert_array_equal(np.asarray(T.persistent(f, "demo", "k")(x, y)["s"]), np.asarray(first["s"]))


def test_an_unwritable_cache_folder_warns_and_runs_the_program(tmp_path, monkeypatch):
    blocked = tmp_path / "file"
    blocked.write_text("a file where the folder would be")
    monkeypatch.setenv("DELTAJAX_PROGRAM_CACHE", str(blocked))
    T._LOADED.clear()
    x = np.arange(3.0)
    with pytest.warns(UserWarning, match="cannot keep the (program|executable)") as caught:
        out = T.persistent(jax.jit(_fn), "demo", "k")(x, x)
    assert sorted(str(w.message).split()[3] for w in caught) == ["executable", "program"]
    np.testing.assert_array_equal(np.asarray(out["s"]), np.asarray(_fn(x, x)["s"]))
    T._LOADED.clear()


def test_a_full_cache_disk_warns_leaves_no_partial_file_and_runs_the_program(tmp_path, monkeypatch):
    import errno

    import deltajax.io as dio

    def full_disk(fd, data):   # half written, then no space
        os.write(fd, bytes(data)[: len(data) // 2])
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setenv("DELTAJAX_PROGRAM_CACHE", str(tmp_path))
    monkeypatch.setattr(dio, "_write_all", full_disk)
    T._LOADED.clear()
    x = np.arange(3.0)
    with pytest.warns(UserWarning, match="cannot keep the (program|executable) .*No space left on device") as caught:
        out = T.persistent(jax.jit(_fn), "demo", "k")(x, x)
    assert sorted(str(w.message).split()[3] for w in caught) == ["executable", "program"]
    assert not [p.name for p in tmp_path.rglob("*") if p.is_file()]    # neither a partial file nor a temporary
    np.testing.assert_array_equal(np.asarray(out["s"]), np.asarray(_fn(x, x)["s"]))
    T._LOADED.clear()


def test_no_cache_folder_runs_the_function_itself(monkeypatch, tmp_path):
    monkeypatch.setenv("DELTAJAX_PROGRAM_CACHE", "")
    assert T.program_cache_dir() is None
    before = dict(T.STATS)
    T.persistent(jax.jit(_fn), "demo", "k")(np.ones(2), np.ones(2))
    assert T.STATS == before


def test_a_program_key_changes_with_the_source_and_the_settings(program_cache):
    key = T._environment_key()
    assert "x64=True" in key and "jax==" in key
    assert len(T._source_fingerprint()) == 64


@pytest.mark.slow   # two processes build the designer's cheap evaluator at the toy size (~40 CPU-s cold)
def test_a_second_process_reads_the_designers_evaluator_without_tracing_the_designer(tmp_path):
    script = textwrap.dedent(f"""
        import sys, numpy as np, jax
        jax.config.update("jax_enable_x64", True)
        sys.path.insert(0, {os.path.dirname(__file__)!r})
        from _config_helpers import compose
        from toy_jobs import JAX_CACHE
        jax.config.update("jax_compilation_cache_dir", JAX_CACHE)
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
        from test_tolerance import TOY_PROBLEM
        from deltajax.config import ga_reconfig_build, robot_from_config
        import deltajax.optimize.designer as D
        from deltajax import tracing as T
        from deltajax.optimize import programs as PR
        from deltajax.optimize.programs import batch_evaluator
        calls = []
        real = D.evaluate_designer
        PR.evaluate_designer = lambda *a, **k: (calls.append(1), real(*a, **k))[1]   # what the programs call
        cfg = compose("ga_reconfig", *TOY_PROBLEM)
        robot, recon = robot_from_config(cfg.robot)
        _, space, pb, _ = ga_reconfig_build(cfg.experiment, robot, recon)
        out = batch_evaluator(pb, space, 4, regular=False)(np.stack([space.baseline_genes()] * 2))
        print("RESULT", len(calls), T.STATS["exported"], T.STATS["loaded"], out["picks_per_min"].tolist())
    """)
    env = {**os.environ, "DELTAJAX_PROGRAM_CACHE": str(tmp_path)}

    def run():
        r = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=600)
        assert r.returncode == 0, r.stderr[-3000:]
        line = [ln for ln in r.stdout.splitlines() if ln.startswith("RESULT")][0].split(maxsplit=4)
        return int(line[1]), int(line[2]), int(line[3]), line[4]

    traced, exported, loaded, picks = run()
    assert (traced, exported, loaded) == (1, 1, 0)
    traced2, exported2, loaded2, picks2 = run()
    assert (traced2, exported2, loaded2) == (0, 0, 1)          # the designer's Python did not run
    assert picks2 == picks


@pytest.mark.slow   # two warm toy runs of the main job, each in a new process (~35 CPU-s each)
def test_a_second_process_of_the_main_job_builds_no_new_program(toy_run, tmp_path):
    # The session's toy run of the main job (the shared fixture) traced and kept every program. Two new processes
    # run the same settings at the CLI's XLA cache threshold (run.CACHE_MIN_COMPILE_S) on an empty XLA cache of
    # their own: the first reads the kept programs back (none exported again) and compiles the rest, the single
    # operations dispatched eagerly included, into that cache; the second then compiles nothing (every compilation
    # a cache hit, no entry written).
    toy_run("ga_reconfig")
    xla = tmp_path / "xla"
    script = textwrap.dedent(f"""
        import collections, sys, jax
        jax.config.update("jax_enable_x64", True)
        sys.path.insert(0, {os.path.dirname(__file__)!r})
        from jax import monitoring
        events, secs = collections.Counter(), collections.Counter()
        monitoring.register_event_listener(lambda name, **kw: events.update([name]))
        def duration(name, s, **kw):
            secs[name] += s
        monitoring.register_event_duration_secs_listener(duration)
        from toy_jobs import overrides
        from deltajax.run import run_experiment
        from deltajax import tracing as T
        args = [o for o in overrides("ga_reconfig") if not o.startswith("compilation_cache=")]
        run_experiment("ga_reconfig", args + [{f"compilation_cache={xla}"!r}], run_dir=sys.argv[1])
        print("RESULT", T.STATS["exported"], T.STATS["loaded"], events["/jax/compilation_cache/cache_misses"],
              events["/jax/compilation_cache/cache_hits"], events["/jax/compilation_cache/compile_requests_use_cache"],
              round(secs["/jax/core/compile/jaxpr_trace_duration"], 2))
        print("KINDS", *T.kinds_in_use())
    """)
    env = {k: v for k, v in os.environ.items() if k != "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"}
    kept = T.program_cache_dir()
    assert kept is not None, "the session keeps no programs (DELTAJAX_PROGRAM_CACHE is empty)"
    env["DELTAJAX_PROGRAM_CACHE"] = str(kept)   # the session's kept programs
    results = []
    for run in ("first", "second"):
        r = subprocess.run([sys.executable, "-c", script, str(tmp_path / run)], env=env, capture_output=True,
                           text=True, timeout=900)
        assert r.returncode == 0, r.stderr[-3000:]
        line = [ln for ln in r.stdout.splitlines() if ln.startswith("RESULT")][0].split()
        results.append((*map(int, line[1:6]), float(line[6])))
    (_, _, written_1, _, requests_1, _), (exported, loaded, written, hits, requests, trace_s) = results
    print(f"first process: {written_1} of {requests_1} compilations written to the XLA cache; second process: "
          f"{loaded} programs read back, {hits} of {requests} compilations from the XLA cache, tracing {trace_s} s")
    assert written_1 > 0 and requests_1 == requests  # the first compiled what the kept programs leave
    assert exported == 0 and loaded > 0        # no program traced and exported anew: each was read back
    assert written == 0 and hits == requests > 0   # every compilation read back from the XLA cache, none anew
    # the export and report stages' programs (datasheet, run report) are among those read back, not traced again
    kinds = set([ln for ln in r.stdout.splitlines() if ln.startswith("KINDS")][0].split()[1:])
    assert {"datasheet_rate", "datasheet_cylinder", "report_good_any", "report_cycle"} <= kinds, kinds
