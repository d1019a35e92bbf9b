"""Which FMU file a scenario's plant.fmu names: a bundled plant (built on demand) or a path."""
from __future__ import annotations

from pathlib import Path

from prlpid_fmi.errors import PlantError
from prlpid_fmi.fmu import bundled_fmu, bundled_plant_names
from prlpid_fmi.fmu.description import describe_fmu


def resolve_fmu(fmu: str, fmi_version: int = 2) -> Path:
    """A bundled plant's name -> its (freshly built if needed) FMU; otherwise the path itself."""
    if fmu in bundled_plant_names():
        return bundled_fmu(fmu, fmi_version)
    path = Path(fmu)
    if not path.is_file():
        from prlpid_fmi.fmu.description import missing_fmu_text
        raise PlantError(f"{fmu}: {missing_fmu_text(path)} (and not a bundled plant: "
                         f"{', '.join(bundled_plant_names())})")
    return path


def loop_units(config) -> tuple[list[str], list[str]]:
    """Units of each loop's output and input from the FMU description of config.fmu (a TuningConfig),
    "" where unknown or unreadable: a label must not fail because the FMU moved."""
    try:
        d = describe_fmu(resolve_fmu(config.fmu, config.fmi_version))
    except Exception:
        return [""] * len(config.loops), [""] * len(config.loops)
    return [d.unit_of(l.output) for l in config.loops], [d.unit_of(l.input) for l in config.loops]
