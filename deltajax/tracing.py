"""Trace a kernel once per process, however many programs call it.

A function decorated with :func:`traced_once` is traced by JAX the first time it is called with a given
structure (the non-array arguments by value, the arrays by shape and dtype) and every later call -- from another
call site of the same program, another program, under ``vmap``, ``jvp`` or ``grad`` -- reuses that trace: JAX
transforms the cached program instead of running the Python again. ``jax.jit(..., inline=True)`` does this and
then inlines the program at each call site, so every caller computes exactly what it computed with the function
traced in place (a nested, not inlined call can change the last bit of a result inside a loop).

Why: the designer's evaluator calls :func:`deltajax.constraints.good_point` at three sites (the sample grid and
the two cylinder searches), and each of those calls the base-plate distance at three forearms; tracing the
Python of each call site again was most of the time a run of the main job spent building its programs.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Any, Callable, Mapping, TypeVar
import hashlib
import importlib.metadata as md
import os
import platform
import pickle
import warnings
from pathlib import Path

import equinox as eqx
import jax
import numpy as np
from jax.experimental import serialize_executable as se
from jax import export

from deltajax.io import write_atomic

__all__ = ["traced_once", "persistent", "program_cache_dir", "cpu_flags", "STATS", "PROGRAMS_KEPT", "content_key",
           "stable_key", "shared_program", "PROGRAMS", "PROGRAMS_MAX", "forget", "kinds_in_use"]

F = TypeVar("F", bound=Callable)


def traced_once(fn: F) -> F:
    """``fn`` with its trace shared by every call of the same structure (see the module docstring).

    The arguments may be any pytrees (equinox modules, NamedTuples, dicts): their array leaves (JAX arrays,
    tracers, NumPy arrays and scalars) are the traced inputs; every other leaf (Python numbers, strings, None,
    tuples of them) is part of the cache key, as it is a constant of the traced program.
    """
    @functools.partial(jax.jit, static_argnums=(0, 1), inline=True)
    def run(treedef, static, dynamic):
        leaves = list(static)
        it = iter(dynamic)
        leaves = [next(it) if s is _ARRAY else s for s in leaves]
        args, kwargs = jax.tree_util.tree_unflatten(treedef, leaves)
        return fn(*args, **kwargs)

    @functools.wraps(fn)
    def call(*args, **kwargs):
        leaves, treedef = jax.tree_util.tree_flatten((args, kwargs))
        arrays = [x for x in leaves if eqx.is_array(x)]
        static = tuple(_ARRAY if eqx.is_array(x) else x for x in leaves)
        return run(treedef, static, arrays)

    call.__wrapped_trace__ = run
    return call  # type: ignore[return-value]


class _ArrayMarker:
    """Stands for an array leaf in the static part of the key."""

    __slots__ = ()

    def __repr__(self) -> str:
        return "<array>"


_ARRAY = _ArrayMarker()


# -- programs kept across processes ---------------------------------------------------------------------------
# JAX's persistent compilation cache keeps the *compiled* programs between processes, but every process still
# runs the Python that builds them (tracing, batching, lowering to StableHLO) before it can look them up: for the
# designer's evaluators that was most of a warm run's program-building time. :func:`persistent` keeps the lowered
# program itself (``jax.export``'s serialisation) on disk, keyed by everything that determines it: the caller's
# key (the content of the problem it closes over), the input shapes and dtypes, this package's source, the
# versions of the libraries that trace it, and the numerics settings. Beside it goes the program compiled for this
# machine (``jax.experimental.serialize_executable``): a process that finds that deserialises it and runs it; one
# that finds only the exported program compiles it once and keeps the executable. The numbers are the exported
# program's in every process, the first one included (a test checks them against the program traced in place,
# bit for bit). JAX's cache alone would still lower each kept program and hash it in every process (~2.7 CPU-s
# of a warm default run of the main job).

def _source_fingerprint() -> str:
    root = Path(__file__).resolve().parent
    h = hashlib.sha256()
    for p in sorted(root.rglob("*.py")):
        h.update(str(p.relative_to(root)).encode())
        h.update(p.read_bytes())
    return h.hexdigest()


@functools.lru_cache(maxsize=None)
def _environment_key() -> str:
    parts = [_source_fingerprint()]
    for dist in ("jax", "jaxlib", "equinox", "numpy"):
        try:
            parts.append(f"{dist}=={md.version(dist)}")
        except md.PackageNotFoundError:
            parts.append(f"{dist}==none")
    parts += [f"x64={jax.config.jax_enable_x64}", f"backend={jax.default_backend()}",
              f"device={jax.devices()[0].device_kind}", f"XLA_FLAGS={os.environ.get('XLA_FLAGS', '')}",
              f"precision={jax.config.jax_default_matmul_precision}"]
    return "\n".join(parts)


def program_cache_dir():
    """Where :func:`persistent` keeps programs: ``$DELTAJAX_PROGRAM_CACHE`` (empty: nowhere), else ``programs/``
    beside JAX's persistent compilation cache (``compilation_cache`` of the run's config), else nowhere (each
    process then traces its programs, as before)."""
    env = os.environ.get("DELTAJAX_PROGRAM_CACHE")
    if env is not None:
        return Path(env).expanduser() if env else None
    d = jax.config.jax_compilation_cache_dir
    return Path(d).expanduser().parent / "programs" if d else None


#: programs kept per kind; beyond it the least recently written go (each edit of the package's source, each new
#: problem content or input shape adds one)
PROGRAMS_KEPT = 64

#: programs exported or read by this process: (kind, hash of key and input structure) -> jitted call of the
#: exported program
_LOADED: dict = {}
#: what :func:`persistent` did in this process (``exported``: traced and written, ``loaded``: read from disk)
STATS = {"exported": 0, "loaded": 0}


def kinds_in_use() -> list:
    """The kinds of the programs :func:`persistent` exported or read back in this process, sorted."""
    return sorted({kind for kind, _ in _LOADED})


def persistent(fn: Callable, kind: str, key: str) -> Callable:
    """``fn`` (a jitted function of pytrees of arrays) built once for all processes: each call with a new input
    structure looks for its exported program under ``kind`` / ``key`` (the content of whatever ``fn`` closes
    over, a string) and the input structure and shapes; if none is on disk it traces and exports ``fn`` and
    writes the program (atomically), and its compiled executable for this machine beside it. Either way the
    exported program runs, so every process computes the same numbers. Inputs and outputs may be any registered
    pytrees (equinox modules, the GA's evosax state): the program itself takes and returns their leaves. With no
    :func:`program_cache_dir`, ``fn`` itself runs."""
    def call(*args):
        root = program_cache_dir()
        if root is None:
            return fn(*args)
        leaves, in_tree = jax.tree_util.tree_flatten(args)
        spec = [jax.ShapeDtypeStruct(jax.numpy.shape(a), jax.numpy.result_type(a)) for a in leaves]
        h = hashlib.sha256("\n".join([_environment_key(), kind, key, repr(in_tree), repr(spec)]).encode())
        h = h.hexdigest()[:32]
        prog = _LOADED.get((kind, h))
        if prog is None:
            prog = _load_or_compile(fn, in_tree, spec, root / kind / f"{h}.jaxexport")
            _LOADED[(kind, h)] = prog
        run, out_tree = prog
        return jax.tree_util.tree_unflatten(out_tree, run(*leaves))

    return call


_MAGIC = b"deltajax-program-1\n"
_EXEC_MAGIC = b"deltajax-executable-1\n"
#: a compile option that changes nothing but the key in JAX's compilation cache (it formats XLA's debug dumps,
#: which only ``xla_dump_to`` turns on): a kept program is compiled under it with the cache's writes off, so it
#: is always compiled afresh -- an executable JAX read back from its cache serialises without its kernels
_FRESH_COMPILE = {"xla_dump_large_constants": True}


@functools.lru_cache(maxsize=None)
def cpu_flags() -> str:
    """This machine's CPU features as ``/proc/cpuinfo`` lists them: its first ``flags`` line (``Features`` on Arm),
    empty where there is none."""
    try:
        with open("/proc/cpuinfo") as f:
            return next((ln for ln in f if ln.startswith(("flags", "Features"))), "")
    except OSError:
        return ""


@functools.lru_cache(maxsize=None)
def _machine_key() -> str:
    """What a compiled executable depends on beyond the exported program: the XLA backend's version and this
    machine's instruction set (XLA:CPU compiles for the host's CPU features)."""
    parts = [platform.machine(), platform.processor(), cpu_flags(), jax.devices()[0].client.platform_version]
    return hashlib.sha256("\n".join(parts).encode()).hexdigest()[:16]


def _read_kept(path, magic: bytes, what: str):
    """(header, payload) of a kept file: ``magic``, the pickled header's length (8 bytes), the header, the payload."""
    data = path.read_bytes()
    if not data.startswith(magic):
        raise ValueError(f"not a deltajax {what} file")
    n = int.from_bytes(data[len(magic):len(magic) + 8], "little")
    head = len(magic) + 8
    return pickle.loads(data[head:head + n]), data[head + n:]


def _write_kept(path, magic: bytes, header, payload: bytes, what: str) -> None:
    """Write a kept file (:func:`_read_kept`'s layout) atomically (:func:`deltajax.io.write_atomic`); a folder
    that cannot hold it warns and the process runs the program all the same."""
    head = pickle.dumps(header)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_atomic(path, magic + len(head).to_bytes(8, "little") + head + payload)
        _evict(path.parent)
    except OSError as err:   # a read-only or full cache folder: this process runs the program all the same
        cause = os.strerror(err.errno) if err.errno else str(err)
        warnings.warn(f"cannot keep the {what} {path} ({cause}); later processes will build it again", stacklevel=4)


def _compile_fresh(run, spec):
    """``run`` (a jitted function) compiled for ``spec`` by XLA, not read from JAX's compilation cache (see
    :data:`_FRESH_COMPILE`), and not written to it (the caller keeps it). It raises the process-wide cache
    threshold for the compile's duration, so it is not for concurrent threads: deltajax builds its programs
    from the calling thread only (its only threads are the Numba drivers', which compile nothing in JAX)."""
    key = "jax_persistent_cache_min_compile_time_secs"
    before = getattr(jax.config, key)
    jax.config.update(key, float("inf"))
    try:
        return run.lower(*spec).compile(compiler_options=_FRESH_COMPILE)
    finally:
        jax.config.update(key, before)


class _Kept:
    """A kept program's call of the leaves: concrete inputs run the compiled executable; inputs traced by an
    enclosing ``jit`` (the resumed GA calls a kept program inside its own) run the exported program's jitted call,
    read when first needed (an executable is compiled for one signature and takes no tracers). The exported
    program is not differentiable and has no batching rule: ``grad`` or ``vmap`` around a kept program fails
    with JAX's error, never with different numbers."""

    def __init__(self, compiled, traceable: Callable[[], Callable]):
        self.compiled, self._traceable, self._jitted = compiled, traceable, None

    def __call__(self, *leaves):
        if any(isinstance(x, jax.core.Tracer) for x in leaves):
            if self._jitted is None:
                self._jitted = self._traceable()
            return self._jitted(*leaves)
        return self.compiled(*leaves)


def _load_or_compile(fn: Callable, in_tree, spec, path):
    """(:class:`_Kept` call of the leaves, output tree) of the exported program at ``path``
    (:func:`_load_or_export`), run as a compiled executable kept beside it for this machine
    (``<hash>.<machine>.xlaexec``): a process that finds it deserialises it and calls it, without lowering the
    exported program or computing JAX's cache key (both paid per process for every kept program) -- the same
    executable, so the same numbers in every process."""
    exe = path.with_name(f"{path.stem}.{_machine_key()}.xlaexec")
    if exe.is_file():
        try:
            (in_c, out_c, out_tree), payload = _read_kept(exe, _EXEC_MAGIC, "executable")
            compiled = se.deserialize_and_load(payload, in_c, out_c)
            STATS["loaded"] += 1
            return _Kept(compiled, lambda: _load_or_export(fn, in_tree, spec, path)[0]), out_tree
        except Exception as err:  # noqa: BLE001 - a damaged cache entry is rebuilt (it holds no results)
            warnings.warn(f"rebuilding the cached program {exe} ({type(err).__name__}: {err})", stacklevel=3)
    run, out_tree = _load_or_export(fn, in_tree, spec, path)
    compiled = _compile_fresh(run, spec)
    payload, in_c, out_c = se.serialize(compiled)
    _write_kept(exe, _EXEC_MAGIC, (in_c, out_c, out_tree), payload, "executable")
    return _Kept(compiled, lambda: run), out_tree


def _load_or_export(fn: Callable, in_tree, spec, path):
    if path.is_file():
        try:
            out_tree, payload = _read_kept(path, _MAGIC, "program")
            exp = export.deserialize(bytearray(payload))
            STATS["loaded"] += 1
            return jax.jit(exp.call), out_tree
        except Exception as err:  # noqa: BLE001 - a damaged cache entry is rebuilt (it holds no results)
            warnings.warn(f"rebuilding the cached program {path} ({type(err).__name__}: {err})", stacklevel=3)
    trees = {}

    def flat(*leaves):
        out, trees["out"] = jax.tree_util.tree_flatten(fn(*jax.tree_util.tree_unflatten(in_tree, leaves)))
        return out

    program = export.export(jax.jit(flat))(*spec).serialize()
    _write_kept(path, _MAGIC, trees["out"], program, "program")
    STATS["exported"] += 1
    return jax.jit(export.deserialize(bytearray(program)).call), trees["out"]


def _evict(folder) -> None:
    for pattern in ("*.jaxexport", "*.xlaexec"):
        try:
            files = sorted(folder.glob(pattern), key=lambda p: p.stat().st_mtime)
        except OSError:   # a file removed by another process meanwhile: evict the next time
            continue
        for p in files[:max(len(files) - PROGRAMS_KEPT, 0)]:
            try:
                p.unlink()
            except OSError:   # another process removed it first
                pass


# -- programs shared by content within a process --------------------------------------------------------------
# Every run builds its problem and design space afresh, and a jitted closure over a fresh object is traced and
# compiled again (a toy run traces its stages for ~40 CPU-s before any compile). The stages' programs are kept
# here under the *content* of the problem and space they close over, so a resumed run, a rerun or another run
# with the same grids in the same process reuses them: the same content gives the same program, hence the same
# numbers as compiling it afresh.
PROGRAMS: dict = {}
PROGRAMS_MAX = 24


def content_key(x) -> Any:
    """A hashable value of everything ``x`` holds (dataclasses and equinox modules field by field, arrays by
    dtype, shape and bytes); an object it cannot see into is keyed by identity (never a false match: the cached
    program keeps it alive)."""
    if isinstance(x, (np.ndarray, np.generic)) or type(x).__module__.startswith("jax"):
        try:
            a = np.asarray(x)
        except Exception:  # noqa: BLE001 - not an array after all (e.g. a tracer): identity
            return ("id", id(x))
        if a.dtype != object:
            return ("array", a.dtype.str, a.shape, a.tobytes())
        return ("objects", a.shape, tuple(content_key(v) for v in a.reshape(-1)))
    if x is None or isinstance(x, (bool, int, float, complex, str, bytes)):
        return (type(x).__name__, repr(x))
    if dataclasses.is_dataclass(x) and not isinstance(x, type):
        return (type(x).__module__, type(x).__qualname__,
                tuple((f.name, content_key(getattr(x, f.name))) for f in dataclasses.fields(x)))
    if isinstance(x, (tuple, list)):
        return (type(x).__qualname__, tuple(content_key(v) for v in x))
    if isinstance(x, Mapping):
        return ("mapping", tuple(sorted((repr(k), content_key(v)) for k, v in x.items())))
    return ("id", id(x))


def stable_key(*objs) -> Any:
    """A string naming the content of ``objs`` in every process (:func:`content_key`'s value, hashed), or None
    when part of it is only known by identity (such a program is not kept across processes)."""
    def by_value(k) -> bool:
        if isinstance(k, tuple):
            if len(k) == 2 and k[0] == "id":
                return False
            return all(by_value(v) for v in k)
        return True

    k = tuple(content_key(o) for o in objs)
    return hashlib.sha256(repr(k).encode()).hexdigest() if by_value(k) else None


def shared_program(kind: str, pb, space, settings: tuple, build: Callable[[], Any], *,
                   persist: bool = False) -> Any:
    """The program ``build()`` for (``kind``, the content of ``pb`` and ``space``, ``settings``), built once per
    process (least recently used dropped beyond ``PROGRAMS_MAX``). ``persist``: ``build()`` is a jitted function
    of arrays whose lowered program is also kept across processes (:func:`deltajax.tracing.persistent`), when the
    content is known by value (:func:`stable_key`)."""
    if persist:
        inner = build

        def build():
            key = stable_key(pb, space, settings)
            return inner() if key is None else persistent(inner(), kind, key)

    key = (kind, content_key(pb), content_key(space), settings)
    if key in PROGRAMS:
        PROGRAMS[key] = PROGRAMS.pop(key)          # most recently used last
    else:
        PROGRAMS[key] = build()
        while len(PROGRAMS) > PROGRAMS_MAX:
            PROGRAMS.pop(next(iter(PROGRAMS)))
    return PROGRAMS[key]


def forget(kind: str) -> int:
    """Drop this process's programs of ``kind`` (:func:`shared_program`, :func:`persistent`): a program a job will
    not call again gives back its compiled code (a certify program at its densest held ~0.3 GiB). Programs kept on
    disk stay there. Returns how many were dropped."""
    mine = [k for k in PROGRAMS if k[0] == kind] + [k for k in _LOADED if k[0] == kind]
    for k in mine:
        PROGRAMS.pop(k, None)
        _LOADED.pop(k, None)
    return len(mine)
