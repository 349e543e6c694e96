"""A wheel is a complete install: configs ship inside it, and the CLI runs from outside the repository."""

import os
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent


def _run(cmd, **kw):
    out = subprocess.run(cmd, capture_output=True, text=True, timeout=600, **kw)
    assert out.returncode == 0, f"{cmd}\n{out.stdout[-2000:]}\n{out.stderr[-3000:]}"
    return out


@pytest.mark.slow
def test_wheel_installs_and_runs_outside_the_repo(tmp_path):
    # build from a clean copy of the sources (no stale build/ of the working tree)
    src = tmp_path / "src"
    shutil.copytree(REPO, src, ignore=shutil.ignore_patterns(".git", "build", "dist", "outputs", "*.egg-info",
                                                             "__pycache__", ".pytest_cache", ".hypothesis"))
    _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(tmp_path / "dist"), str(src)])
    (wheel,) = (tmp_path / "dist").glob("deltajax-*.whl")
    # a fresh venv with only the wheel installed; the dependencies (jax, ...) are seen through a .pth file
    # pointing at this interpreter's site-packages, so nothing is downloaded (path lines of a .pth do not
    # run that directory's own .pth files, so an editable deltajax there stays invisible)
    venv = tmp_path / "venv"
    _run([sys.executable, "-m", "venv", "--without-pip", str(venv)])
    vpy = venv / "bin" / "python"
    _run([sys.executable, "-m", "pip", "--python", str(vpy), "install", "--no-deps", "-q", str(wheel)])
    site = Path(_run([str(vpy), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"]).stdout.strip())
    deps = {sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]}
    (site / "_deltajax_test_deps.pth").write_text("\n".join(sorted(deps)) + "\n")
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "DELTAJAX_CONFIG_DIR", "HYDRA_FULL_ERROR")}
    work = tmp_path / "elsewhere"
    work.mkdir()
    where = _run([str(vpy), "-c", "import deltajax, deltajax.run as r; print(deltajax.__file__); print(r.CONFIG_DIR)"],
                 cwd=work, env=env).stdout.split()
    assert all(str(venv) in w for w in where), where  # the wheel's package and its shipped configs
    helped = _run([str(venv / "bin" / "deltajax"), "--help"], cwd=work, env=env)
    assert "ga_reconfig" in helped.stdout and "indices_examples" in helped.stdout
    # the session's XLA cache (DELTAJAX_JAX_CACHE from tests/conftest.py, read by the wheel's own config.yaml)
    _run([str(venv / "bin" / "deltajax"), "experiment=indices_examples", "experiment.R_step=1e-3", "plots=false",
          "hydra.run.dir=run"], cwd=work, env=env)
    assert (work / "run" / "results.h5").stat().st_size > 10_000
    assert "wrote" in (work / "run" / "run.log").read_text()
