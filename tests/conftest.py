import pytest

from prlpid_fmi.fmu import bundled_fmu, bundled_plant_names

PLANTS = bundled_plant_names()


@pytest.fixture(scope="session", params=[2, 3], ids=["fmi2", "fmi3"])
def fmi_version(request):
    return request.param


def fmu(name: str, version: int = 2):
    """Path of a bundled FMU, built on demand (cached in the per-user FMU cache)."""
    return bundled_fmu(name, version)
