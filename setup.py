"""Ship the top-level ``configs/`` inside the wheel as ``deltajax/configs`` (package data).

The repository keeps ``configs/`` at the top (the layout Hydra users know); a wheel or a non-editable
``pip install .`` has no repository around it, so ``build_py`` copies the tree into the built package, where
:data:`deltajax.run.CONFIG_DIR` finds it. Everything else is declared in pyproject.toml.
"""

import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py as _build_py


class build_py(_build_py):
    def run(self):
        super().run()
        if getattr(self, "editable_mode", False):
            return  # an editable install reads the repository's configs/ directly
        src = Path(__file__).resolve().parent / "configs"
        dst = Path(self.build_lib) / "deltajax" / "configs"
        shutil.copytree(src, dst, dirs_exist_ok=True, ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))


setup(cmdclass={"build_py": build_py})
