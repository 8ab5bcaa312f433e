"""The build step pyproject.toml cannot say: the annotation page's JavaScript goes into the wheel.

The page loads three.js, urdf-loader and iwer from npm (package-lock.json pins them). A wheel built from a
checkout carries exactly the files of their module graph the page loads (mrguide.annotation.page_assets),
with the packages' licences, so `pip install .` serves a working page. Without `node_modules` the build runs
`npm ci`; where npm is missing too, it builds the rest and says so (the server then refuses to start with
the reason), so a robot PC without Node.js still installs mrguide.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

HERE = Path(__file__).resolve().parent
WEB = HERE / "mrguide" / "annotation" / "web"


def _page_assets():
    sys.path.insert(0, str(HERE))
    try:
        from mrguide.annotation.page_assets import module_files  # standard library only
    finally:
        sys.path.pop(0)
    return module_files


class BuildWithPage(build_py):
    def run(self) -> None:
        super().run()
        if not (WEB / "node_modules").is_dir():
            npm = shutil.which("npm")
            if npm is None:
                print(
                    "warning: npm not found: the wheel has no annotation page scripts (mrguide train --expert live "
                    "will say so); install Node.js and build again for a wheel with the page",
                    file=sys.stderr,
                )
                return
            subprocess.run([npm, "ci", "--no-audit", "--no-fund", "--loglevel=error"], cwd=WEB, check=True)
        target = Path(self.build_lib) / "mrguide" / "annotation" / "web"
        for path in _page_assets()(WEB):
            out = target / path.relative_to(WEB.resolve())
            out.parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(path, out)


setup(cmdclass={"build_py": BuildWithPage})
