"""The documentation stays honest: README within its size, every job, config name, repository path and results
group the README and docs/ mention exists, the README's commands are the ones CI runs, no machine path in any
tracked file, the sources cite only documents the repository holds, and the README's code runs."""

from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
README = REPO / "README.md"
DOCS = sorted((REPO / "docs").glob("*.md"))
MAX_LINES, MAX_WORDS = 150, 1200
#: launcher names that come from Hydra's plugins, not from configs/hydra/launcher
PLUGIN_LAUNCHERS = {"joblib", "submitit_slurm", "submitit_local", "basic"}
#: tracked files may name this folder: the SLURM test cluster's default state folder (.ci/slurm-up)
ALLOWED_MACHINE_PATHS = ("/tmp/deltajax-slurm",)
MACHINE_PATH = re.compile(r"(?<![\w.~-])/(?:work|root|home|tmp)/")
REPO_PATH = re.compile(r"(?<![\w./<-])((?:deltajax|configs|docs|tests|experiments|\.ci|outputs)/[\w./*<>{}-]*"
                       r"(?:::[\w*]+)?)")


def _texts():
    return [(p.relative_to(REPO).as_posix(), p.read_text()) for p in [README, *DOCS]]


def _names(directory: str) -> set:
    return {p.stem for p in (REPO / directory).glob("*.yaml")}


def test_readme_is_short():
    text = README.read_text()
    lines, words = len(text.splitlines()), len(text.split())
    assert lines <= MAX_LINES and words <= MAX_WORDS, f"README: {lines} lines, {words} words"


def test_every_experiment_named_exists():
    have = _names("configs/experiment")
    missing = []
    for name, text in _texts():
        for m in re.finditer(r"(?<![\w.])experiment=([\w,]+)", text):
            missing += [(name, e) for e in m.group(1).split(",") if e and not e.isupper() and e not in have]
    assert not missing, missing


def test_every_robot_and_launcher_named_exists():
    robots, launchers = _names("configs/robot"), _names("configs/hydra/launcher") | PLUGIN_LAUNCHERS
    missing = []
    for name, text in _texts():
        missing += [(name, r) for r in re.findall(r"(?<![\w.])robot=(\w+)", text) if r not in robots]
        missing += [(name, h) for h in re.findall(r"hydra/launcher=(\w+)", text) if h not in launchers]
    assert not missing, missing


def test_every_repository_path_named_exists():
    missing = []
    for name, text in _texts():
        for m in REPO_PATH.finditer(text):
            token = m.group(1)
            if any(c in token for c in "<>*{}") or "..." in token:
                continue  # a pattern or placeholder, not a file
            path, _, symbol = token.rstrip(".,;:").partition("::")
            if not (REPO / path).exists():
                missing.append((name, token))
            elif symbol and not re.search(rf"^\s*(?:def|class)\s+{symbol}\b|^{symbol}\s*=", (REPO / path).read_text(),
                                          re.M):
                missing.append((name, token))
        base = (REPO / name).parent
        for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", text):
            if not re.match(r"\w+://", target) and not (base / target).exists():
                missing.append((name, target))
    assert not missing, missing


def test_no_machine_paths_in_tracked_files():
    files = subprocess.run(["git", "ls-files"], cwd=REPO, capture_output=True, text=True, check=True).stdout.split()
    found = []
    for f in files:
        try:
            text = (REPO / f).read_text()
        except (UnicodeDecodeError, FileNotFoundError, IsADirectoryError):
            continue
        for m in MACHINE_PATH.finditer(text):
            if not text.startswith(ALLOWED_MACHINE_PATHS, m.start()):
                found.append(f"{f}:{text.count(chr(10), 0, m.start()) + 1}: {text[m.start():m.start() + 40]!r}")
    assert not found, found


def test_readme_commands_are_the_ones_ci_runs():
    ci = (REPO / ".ci" / "run").read_text().splitlines()
    install = next(re.sub(r"\s--quiet\b", "", ln).strip() for ln in ci if re.match(r"\s*pip install .*-e", ln))
    pytest_cmd = next(ln.strip() for ln in ci if ln.strip().startswith("python -m pytest"))
    blocks = re.findall(r"```bash\n(.*?)```", README.read_text(), re.S)
    assert any(install in b and pytest_cmd in b and "python3 -m venv" in b for b in blocks), (install, pytest_cmd)
    main = [b for b in blocks if "python -m deltajax.run experiment=ga_reconfig" in b]
    assert main and "pip install -e ." in main[0]
    assert f'{pytest_cmd} -m "not slow"' in README.read_text()


def _jobs_table():
    """The README's jobs table: {job: (groups, figures)} from its `writes` column."""
    rows = {}
    for line in README.read_text().splitlines():
        m = re.match(r"\| `(\w+)` \|.*\| (.*) \|$", line)
        if m and m.group(1) in _names("configs/experiment"):
            groups, _, figures = m.group(2).partition(";")
            rows[m.group(1)] = (re.findall(r"`([\w/]+)`", groups), re.findall(r"`([^`]+\.png)`", figures))
    return rows


def test_jobs_table_lists_every_job_once():
    assert sorted(_jobs_table()) == sorted(_names("configs/experiment"))


def _package_source() -> str:
    return "\n".join(p.read_text() for p in (REPO / "deltajax").rglob("*.py"))


def _written(group: str, source: str) -> bool:
    """``group`` appears in the package as results groups are named there: the top group as a literal ("a" or
    "a/..."), each subgroup as "/b" or "b" (f"{g}/b")."""
    top, *subs = group.split("/")
    return bool(re.search(rf"""["']{top}["/]""", source)) and all(re.search(rf"""[/"']{s}["/]""", source)
                                                                   for s in subs)


def test_every_nested_group_named_in_readme_exists():
    """A slashed name in the README is a config group (configs/<name>) or a results group the code writes."""
    source = _package_source()
    names = set(re.findall(r"`([a-z_]+(?:/[a-z_]+)+)`", README.read_text()))
    missing = [n for n in names if not (REPO / "configs" / n).is_dir() and not _written(n, source)]
    assert not missing, missing


def test_jobs_table_names_only_groups_and_figures_the_code_writes():
    """A group or figure in the table appears as a string literal in the package (the cheap check; the slow test
    below checks the files of real runs)."""
    source = _package_source()
    missing = []
    for job, (groups, figures) in _jobs_table().items():
        missing += [(job, g) for g in groups if not _written(g, source)]
        for fig in figures:
            parts = [p for p in re.split(r"<\w+>|\*", fig.removesuffix(".png")) if p.strip("_")]
            missing += [(job, fig) for p in parts if p.strip("_") not in source]
    assert not missing, missing


@pytest.mark.slow
@pytest.mark.parametrize("job", sorted(_jobs_table()))
def test_jobs_table_matches_a_real_run(job, toy_run):
    from deltajax.io import groups

    path = toy_run(job)
    have = groups(path)
    table_groups, figures = _jobs_table()[job]
    assert all(any(h == g or h.startswith(g + "/") for h in have) for g in table_groups), (table_groups, have)
    for fig in figures:
        assert list(path.parent.glob(re.sub(r"<\w+>", "*", fig))), fig
    assert (path.parent / "run.log").is_file()  # README: every job writes results.h5, its plots and run.log
    if job == "ga_reconfig":  # docs/results.md: the GA checkpoint stays in the finished file
        assert "ga/checkpoint" in have


@pytest.mark.slow
def test_readme_code_runs():
    """Every Python block of the README, in order, in one namespace (the tour's names and values)."""
    ns: dict = {}
    for block in re.findall(r"```python\n(.*?)```", README.read_text(), re.S):
        exec(compile(block, "README.md", "exec"), ns)  # noqa: S102 - the README's own code
    assert abs(float(ns["ind"].k_tilde) - 0.70362) < 1e-4  # Table 4's point (docs/REPRODUCTION.md §1)
    assert not bool(ns["res"].truncated) and float(ns["res"].volume) > 0
    assert 100 < float(ns["m"].cycles_per_minute) < 110  # 103.1 (docs/REPRODUCTION.md §4)


def test_main_job_run_time_is_stated_alike():
    """README, the job's config header and docs/CLUSTER.md give the same run time (the figure: docs/BENCHMARKS.md)."""
    found = {}
    for f in ("README.md", "configs/experiment/ga_reconfig.yaml", "docs/CLUSTER.md", "docs/design.md"):
        found[f] = set(re.findall(r"(\d+)\s*[–-]\s*(\d+)\s+min(?:utes)?\s+on\s+2\s+cores", (REPO / f).read_text()))
    assert all(found.values()) and len(set.union(*found.values())) == 1, found


def test_sources_cite_only_documents_the_repository_holds():
    """Docstrings, comments and configs point a reader at documents in the repository (``docs/*.md`` that
    exist), never at the project's specification or issue tracker, which a reader of the code does not have."""
    cite = re.compile(r"\bSPEC\s*§|\b[Ii]ssues? #?\d+\b")
    doc = re.compile(r"(?<![\w/.-])docs/[\w.-]+\.md")
    found = []
    for d in ("deltajax", "experiments", "tests", "configs"):
        for p in sorted((REPO / d).rglob("*")):
            if p.suffix not in (".py", ".yaml") or "__pycache__" in p.parts:
                continue
            text = p.read_text()
            found += [f"{p.relative_to(REPO)}: {m.group(0)!r}" for m in cite.finditer(text)]
            found += [f"{p.relative_to(REPO)}: {m.group(0)} (missing)" for m in doc.finditer(text)
                      if not (REPO / m.group(0)).exists()]
    assert not found, found
