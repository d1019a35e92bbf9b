"""Which FMU file a scenario's plant.fmu names: a bundled plant (built on demand) or a path."""
from __future__ import annotations

from pathlib import Path

from prlpid_fmi.errors import PlantError
from prlpid_fmi.fmu.build import bundled_fmu, bundled_plant_names
from prlpid_fmi.fmu.description import describe_fmu, missing_fmu_text


def fmu_file(fmu: str, base_dir: Path | None = None) -> Path:
    """The file a plant.fmu that is not a bundled plant's name points to: ~ expanded, relative to base_dir (a
    scenario's folder) when given and the path is relative."""
    path = Path(fmu).expanduser()
    if base_dir is not None and not path.is_absolute():
        path = (base_dir / path).resolve()
    return path


def resolve_fmu(fmu: str, fmi_version: int = 2, base_dir: Path | None = None) -> Path:
    """A bundled plant's name -> its FMU (built on demand for this FMI version); otherwise fmu_file(fmu,
    base_dir), which must be a file. Raises PlantError (a bundled plant that cannot be built, a missing file)."""
    if fmu in bundled_plant_names():
        return bundled_fmu(fmu, fmi_version)
    path = fmu_file(fmu, base_dir)
    if not path.is_file():
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
