import os

import pytest

from prlpid_fmi import runcontext
from prlpid_fmi.fmu import bundled_fmu, bundled_plant_names
from prlpid_fmi.tuning.search_pool import WORKERS_ENV

# the fixed-PID search in the test's own process: pytest-xdist runs one test file per core already (a search's result
# does not depend on its number of processes: tests/test_search_pool.py checks that, and the pool itself)
os.environ.setdefault(WORKERS_ENV, "1")

PLANTS = bundled_plant_names()


@pytest.fixture
def run_context():
    """A fresh prlpid_fmi.runcontext for the test: no measurements or references kept, the process's own after it."""
    with runcontext.opened() as run:
        yield run


@pytest.fixture(scope="session", params=[2, 3], ids=["fmi2", "fmi3"])
def fmi_version(request):
    return request.param


def fmu(name: str, version: int = 2):
    """Path of a bundled FMU, built on demand (cached in the per-user FMU cache)."""
    return bundled_fmu(name, version)



# -- scheduling on pytest-xdist workers (`--dist loadfile --no-loadscope-reorder`, pyproject's addopts) ------------
# Each test file runs on one worker (its module fixtures, e.g. a trained run, built once); a worker takes the next file
# when the one it runs has at most two tests left. Without --no-loadscope-reorder xdist orders the files by their
# number of tests and ignores this order (the six end-to-end runs, 4.5 min, then started last: 13 min 59 s in a
# clean-clone CI run on 2 cores). The files go longest first (seconds summed per file in a `--durations=0` run, the
# machine otherwise idle), so the two workers end together; the rest follow in collection order.
FIRST = ("test_end_to_end.py", "test_faults.py", "test_sweep.py", "test_packaging.py", "test_third_party_fmus.py",
         "test_open_loop.py", "test_pid_law_spec.py", "test_fmu_faults_exporters.py", "test_actions_anchored.py",
         "test_formats.py", "test_cli_conventions.py", "test_load_design.py", "test_cli.py", "test_classical.py",
         "test_agent.py", "test_candidates.py", "test_search_pool.py", "test_nonlinear_plants.py", "test_adapters.py")


def pytest_collection_modifyitems(config, items):
    def rank(item):
        name = item.nodeid.split("::")[0].split("/")[-1]
        return FIRST.index(name) if name in FIRST else len(FIRST)
    items[:] = sorted(items, key=rank)  # stable: the order within a file is kept
