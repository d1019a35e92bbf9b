import pytest

from prlpid_fmi.fmu import bundled_fmu, bundled_plant_names

PLANTS = bundled_plant_names()


@pytest.fixture(scope="session", params=[2, 3], ids=["fmi2", "fmi3"])
def fmi_version(request):
    return request.param


def fmu(name: str, version: int = 2):
    """Path of a bundled FMU, built on demand (cached in the per-user FMU cache)."""
    return bundled_fmu(name, version)


# -- scheduling on pytest-xdist workers (`--dist loadgroup`, pyproject's addopts) -------------------------------
# A file with module- or session-scoped fixtures (a trained run, built FMUs, a wheel) stays on one worker, so they
# are built once: it is one xdist group. Every other test is scheduled on its own, so one slow file does not
# hold a worker while the other runs out of work. The known long tests and groups go first (xdist deals the first
# quarter of the work round-robin and the rest to whichever worker is free): the tail is made of short tests.
GROUPED_FILES = ("test_benchmark_plants.py", "test_cli_conventions.py", "test_deploy.py", "test_faults.py",
                 "test_fmi_interfaces.py", "test_fmu_faults_exporters.py", "test_nonlinear_plants.py",
                 "test_packaging.py", "test_pid_law_spec.py", "test_plots.py", "test_probe.py", "test_startup.py",
                 "test_sweep.py", "test_third_party_fmus.py", "test_classical_schedule.py")
FIRST = ("test_cli.py::test_every_paper_scenario_runs_end_to_end", "test_classical_schedule.py", "test_packaging.py",
         "test_sweep.py", "test_faults.py", "test_third_party_fmus.py", "test_nonlinear_plants.py",
         "test_fmu_faults_exporters.py")


def pytest_collection_modifyitems(config, items):
    import os

    for item in items:
        name = os.path.basename(item.location[0])
        if name in GROUPED_FILES:
            item.add_marker(pytest.mark.xdist_group(name=name))

    def rank(item):
        nodeid = item.nodeid.split("/")[-1]
        return next((i for i, prefix in enumerate(FIRST) if nodeid.startswith(prefix)), len(FIRST))
    items[:] = sorted(items, key=rank)  # stable: the order within a file is kept
