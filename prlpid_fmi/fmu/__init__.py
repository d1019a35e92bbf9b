"""FMU runtime: load any FMI 2.0/3.0 co-simulation FMU, step it, copy its state; build bundled plants."""
from prlpid_fmi.fmu.build import build_all, build_fmu, bundled_fmu, bundled_plant_names
from prlpid_fmi.fmu.description import FmuDescription, describe_fmu, format_description
from prlpid_fmi.fmu.plant import FmuPlant, StepRejected

__all__ = ["FmuPlant", "StepRejected", "FmuDescription", "describe_fmu", "format_description",
           "bundled_fmu", "build_fmu", "build_all", "bundled_plant_names"]
