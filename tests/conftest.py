import os

import pytest

from prlpid_fmi.fmu import bundled_fmu, bundled_plant_names
from prlpid_fmi.tuning.search_pool import WORKERS_ENV

# the fixed-PID search in the test's own process: pytest-xdist runs one test file per core already (a search's result
# does not depend on its number of processes: tests/test_search_pool.py checks that, and the pool itself)
os.environ.setdefault(WORKERS_ENV, "1")

PLANTS = bundled_plant_names()


@pytest.fixture(scope="session", params=[2, 3], ids=["fmi2", "fmi3"])
def fmi_version(request):
    return request.param


def fmu(name: str, version: int = 2):
    """Path of a bundled FMU, built on demand (cached in the per-user FMU cache)."""
    return bundled_fmu(name, version)



# -- scheduling on pytest-xdist workers (`--dist loadfile`, pyproject's addopts) --------------------------------
# Each test file runs on one worker (its module fixtures, e.g. a trained run, built once). The files with the known
# long tests go first: xdist deals the first quarter of the files round-robin and the rest to whichever worker is
# free, so the tail is made of short files. (Grouping only the files with module fixtures and scheduling every
# other test alone, --dist loadgroup with xdist_group marks added here, split the marked files too under
# pytest-xdist 3.8: their fixtures were built twice; not pursued.)
FIRST = ("test_end_to_end.py", "test_cli.py", "test_sweep.py", "test_faults.py", "test_third_party_fmus.py", "test_packaging.py",
         "test_anchored.py", "test_pid_law_spec.py", "test_classical_schedule.py", "test_nonlinear_plants.py",
         "test_fmu_faults_exporters.py")


def pytest_collection_modifyitems(config, items):
    def rank(item):
        name = item.nodeid.split("::")[0].split("/")[-1]
        return FIRST.index(name) if name in FIRST else len(FIRST)
    items[:] = sorted(items, key=rank)  # stable: the order within a file is kept
