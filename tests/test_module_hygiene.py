"""The package's layout rules, checked on the source (ast, nothing imported): every module declares its public
names, no module imports another module's private names, the engines and the core never touch the results-file
or configuration libraries (h5py, OmegaConf, Hydra) -- only :mod:`deltajax.io` and the application wing do --,
imports run core <- engines <- application, never upward, and a module imports the deltajax modules it uses at
its top (the Numba backend, and the application wing seen from ``import deltajax``, load on first use)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parents[1] / "deltajax"

#: The application wing: the CLI, its settings and run directories, the jobs, sweeps, plots, reports, benchmarks.
APP = ("run", "runlog", "overrides", "schemas", "rundir", "sweep", "merge", "report", "runreport", "config", "jobs",
       "sweeps", "plots", "benchmarks")
#: The engines over the core.
ENGINES = ("workspace", "motion", "motion_refine", "optimize", "datasheet", "export", "tolerance")
#: Third-party libraries of the results file and the configuration: io and the application only.
APP_LIBRARIES = ("h5py", "omegaconf", "hydra", "hydra_plugins", "h5netcdf", "xarray")


def _modules():
    for f in sorted(PKG.rglob("*.py")):
        parts = f.relative_to(PKG.parent).with_suffix("").parts
        yield f, ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = list(_modules())


def _wing(modname: str) -> str:
    parts = modname.split(".")
    top = parts[1] if len(parts) > 1 else ""
    if top in APP:
        return "app"
    if top in ENGINES:
        return "engine"
    return "core"


def _resolve(modname: str, is_pkg: bool, node: ast.ImportFrom) -> str:
    """The absolute module an ImportFrom names."""
    if node.level == 0:
        return node.module or ""
    base = modname.split(".")
    base = base if is_pkg else base[:-1]
    base = base[:len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _imports(f: Path, modname: str):
    """(line, absolute module, imported name or None) for every import in the module, function-level ones too."""
    tree = ast.parse(f.read_text())
    is_pkg = f.name == "__init__.py"
    for n in ast.walk(tree):
        if isinstance(n, ast.Import):
            for a in n.names:
                yield n.lineno, a.name, None
        elif isinstance(n, ast.ImportFrom):
            mod = _resolve(modname, is_pkg, n)
            for a in n.names:
                yield n.lineno, mod, a.name


def _private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__")


@pytest.mark.parametrize("f,modname", MODULES, ids=[m for _, m in MODULES])
def test_module_declares_all_and_its_names_exist(f, modname):
    tree = ast.parse(f.read_text())
    decl = [n for n in tree.body if isinstance(n, (ast.Assign, ast.AnnAssign))
            and any(isinstance(t, ast.Name) and t.id == "__all__"
                    for t in (n.targets if isinstance(n, ast.Assign) else [n.target]))]
    assert decl, f"{modname} has no __all__"
    names = ast.literal_eval(decl[0].value)
    defined = set()

    def collect(body):
        for n in body:
            if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                defined.add(n.name)
            elif isinstance(n, (ast.Import, ast.ImportFrom)):
                defined.update((a.asname or a.name).split(".")[0] for a in n.names)
            elif isinstance(n, (ast.Assign, ast.AnnAssign)):
                for t in (n.targets if isinstance(n, ast.Assign) else [n.target]):
                    defined.update(x.id for x in ast.walk(t) if isinstance(x, ast.Name))
            elif isinstance(n, (ast.If, ast.Try)):          # definitions under a version or import guard
                collect(n.body + n.orelse + [x for h in getattr(n, "handlers", []) for x in h.body])

    collect(tree.body)
    if f.name == "__init__.py":   # a package's submodules are its names too
        defined.update(p.stem for p in f.parent.glob("*.py"))
        defined.update(p.name for p in f.parent.iterdir() if (p / "__init__.py").exists())
    missing = [x for x in names if x not in defined]
    assert not missing, f"{modname}.__all__ names what it does not define: {missing}"
    assert not [x for x in names if _private(x)], f"{modname}.__all__ lists private names"


@pytest.mark.slow
def test_no_private_name_is_imported_across_modules():
    bad = []
    for f, modname in MODULES:
        for line, mod, name in _imports(f, modname):
            if not mod.startswith("deltajax"):
                continue
            # a private submodule may be imported by its own package (``from . import numba_fields`` in deltajax.workspace)
            own_submodule = (PKG.parent / Path(*f"{mod}.{name}".split("."))).with_suffix(".py").exists() and (
                modname == mod or modname.startswith(mod + "."))
            if name is not None and _private(name) and not own_submodule:
                bad.append(f"{modname}:{line} imports {name} from {mod}")
            # a private module (deltajax.workspace.numba_fields, ...) only from inside its own package
            parts = mod.split(".")
            for i, p in enumerate(parts):
                pkg = ".".join(parts[:i])
                if _private(p) and not (modname == pkg or modname.startswith(pkg + ".")):
                    bad.append(f"{modname}:{line} imports the private module {mod}")
    assert not bad, "\n".join(bad)


def test_results_and_config_libraries_only_in_io_and_the_application():
    bad = []
    for f, modname in MODULES:
        if _wing(modname) == "app" or modname == "deltajax.io" or modname.startswith("deltajax.io."):
            continue
        for line, mod, _ in _imports(f, modname):
            if mod.split(".")[0] in APP_LIBRARIES:
                bad.append(f"{modname}:{line} imports {mod}")
    assert not bad, "\n".join(bad)


@pytest.mark.slow
def test_imports_run_core_to_engines_to_application():
    rank = {"core": 0, "engine": 1, "app": 2}
    bad = []
    for f, modname in MODULES:
        if modname == "deltajax":    # the face re-exports every wing
            continue
        for line, mod, name in _imports(f, modname):
            if not mod.startswith("deltajax"):
                continue
            target = mod if name is None or mod != "deltajax" else f"deltajax.{name}"
            if target == "deltajax":
                continue
            if rank[_wing(target)] > rank[_wing(modname)]:
                bad.append(f"{modname}:{line} ({_wing(modname)}) imports {target} ({_wing(target)})")
    assert not bad, "\n".join(bad)


#: where the configuration is read: the settings builders (deltajax.config) and the run that hands their result to
#: the job (deltajax.run); jobs and library read ``RunContext.settings``, never the config
CONFIG_READERS = ("deltajax.config", "deltajax.run")


@pytest.mark.slow
def test_the_configuration_is_read_in_one_place():
    bad = []
    for f, modname in MODULES:
        if modname.startswith(CONFIG_READERS):
            continue
        for n in ast.walk(ast.parse(f.read_text())):
            if isinstance(n, ast.Attribute) and n.attr == "cfg":
                bad.append(f"{modname}:{n.lineno} reads .cfg")
    assert not bad, "\n".join(bad)


#: loaded on first use: the Numba backend (importing it starts Numba; its kernels compile or load on first call)
FIRST_USE = ("deltajax.workspace.numba_", "deltajax.benchmarks")
#: module name -> its file
FILES = {m: f for f, m in MODULES}


def _loaded(node: ast.AST, modname: str, is_pkg: bool) -> set:
    """The deltajax modules an import statement loads: the module, its packages, and submodules named in it."""
    if isinstance(node, ast.ImportFrom):
        mod = _resolve(modname, is_pkg, node)
        names = [mod] + [f"{mod}.{a.name}" for a in node.names if f"{mod}.{a.name}" in FILES]
    else:
        names = [a.name for a in node.names]
    return {".".join(n.split(".")[:i]) for n in names if n.startswith("deltajax")
            for i in range(1, len(n.split(".")) + 1)}


def _function_level(tree: ast.AST):
    """Import statements inside a function body (not under ``try``: an optional dependency)."""
    for fn in ast.walk(tree):
        if isinstance(fn, (ast.FunctionDef, ast.AsyncFunctionDef)):
            stack = list(fn.body)
            while stack:
                n = stack.pop()
                if isinstance(n, (ast.Import, ast.ImportFrom)):
                    yield n
                elif not isinstance(n, (ast.Try, ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                    stack.extend(c for c in ast.iter_child_nodes(n) if isinstance(c, ast.stmt))


def test_deltajax_modules_are_imported_at_module_level():
    """A module imports the deltajax modules it uses at its top, where a reader sees its dependencies. Two kinds
    load on first use: the Numba backend (:data:`FIRST_USE`), and a module that ``import deltajax`` does not load,
    imported by one that it does (``import deltajax`` stays the library, not the application wing)."""
    base, todo = set(), ["deltajax"]
    while todo:                                  # what ``import deltajax`` loads: module-level imports, followed
        m = todo.pop()
        if m in base or m not in FILES:
            continue
        base.add(m)
        for n in ast.parse(FILES[m].read_text()).body:
            if isinstance(n, (ast.Import, ast.ImportFrom)):
                todo += sorted(_loaded(n, m, FILES[m].name == "__init__.py"))
    assert {"deltajax.kinematics", "deltajax.io", "deltajax.workspace"} <= base and "deltajax.jobs" not in base
    bad = []
    for f, modname in MODULES:
        is_pkg = f.name == "__init__.py"
        for n in _function_level(ast.parse(f.read_text())):
            mods = _loaded(n, modname, is_pkg)
            if not mods or any(m.startswith(FIRST_USE) for m in mods):
                continue
            if modname in base and not mods <= base:
                continue
            bad.append(f"{modname}:{n.lineno} imports {sorted(mods)} inside a function")
    assert not bad, "\n".join(bad)
