"""Build hook: a wheel carries the repository's top-level plant_sources/ and scenarios/ as package data.

The folders stay at the top of the repository (one copy, read directly by a checkout or an editable
install); a regular build copies them into prlpid_fmi/plant_sources/ and prlpid_fmi/scenarios/, where
prlpid_fmi.bundled finds them after `pip install`. Everything else is configured in pyproject.toml.
"""
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

BUNDLED = {"plant_sources": ("*.c", "*.h", "*.yaml", "*.mo"), "scenarios": ("*.yaml", "*.json")}


class BuildPyWithBundledData(build_py):
    def run(self):
        super().run()
        if self.editable_mode:  # an editable install reads the checkout's folders in place
            return
        for folder, patterns in BUNDLED.items():
            for pattern in patterns:
                for src in sorted(Path(folder).rglob(pattern)):
                    target = Path(self.build_lib, "prlpid_fmi", src)
                    self.mkpath(str(target.parent))
                    self.copy_file(str(src), str(target))


setup(cmdclass={"build_py": BuildPyWithBundledData})
