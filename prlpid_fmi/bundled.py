"""Where the bundled plant sources and scenarios are read from, and where bundled FMUs are built.

An installed wheel carries plant_sources/ and scenarios/ inside the package (prlpid_fmi/plant_sources/,
prlpid_fmi/scenarios/, mapped there from the repository's top-level folders at build time); a checkout
or an editable install reads the repository's top-level folders. FMUs built from the plant sources go
to a per-user cache folder (platformdirs: ~/.cache/prlpid-fmi/<version>/fmus on Linux, honouring
XDG_CACHE_HOME), never into site-packages or the checkout.
"""
from __future__ import annotations

from pathlib import Path

from prlpid_fmi.version import __version__

PACKAGE_DIR = Path(__file__).resolve().parent
REPO_ROOT = PACKAGE_DIR.parent


def data_dir(name: str) -> Path:
    """The bundled folder `name` ("plant_sources" or "scenarios"): inside the package when installed
    from a wheel, else the repository's top-level folder."""
    packaged = PACKAGE_DIR / name
    return packaged if packaged.is_dir() else REPO_ROOT / name


def fmu_cache_dir() -> Path:
    """Per-user folder for FMUs built from the bundled plant sources (one per package version)."""
    from platformdirs import user_cache_path

    return user_cache_path("prlpid-fmi", appauthor=False, version=__version__) / "fmus"


SCENARIO_DIR = data_dir("scenarios")  # the bundled scenario files (scenarios/<name>.yaml)
