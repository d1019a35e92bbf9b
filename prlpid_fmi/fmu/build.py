"""Build the bundled plants (plant_sources/<Name>/) into FMI 2.0 or 3.0 co-simulation FMUs.

Also, for testing importers: FMI 2.0 model-exchange-only FMUs (`interface="model-exchange"`: the states and
their derivatives are exposed after the model's variables, the importer integrates) and FMI 1.0
co-simulation FMUs (`fmi_version=1`, through the shim plant_sources/common/fmi1_api.c; no FMU state).

Each plant directory holds model.yaml (its variables: the one source of truth), model.c (its
equations) and <Name>.mo (the same equations in Modelica). The build generates variables.h and
modelDescription.xml from model.yaml, puts the shared FMI layer (plant_sources/common/) and the
model into sources/, compiles the binary for this platform with FMPy's CMake support
(``fmpy.build.build_platform_binary``) and zips the result atomically into the per-user FMU cache
(prlpid_fmi.bundled.fmu_cache_dir) or a folder given by the caller.

The instantiation token is a hash of every source file and of the generated files, so an FMU whose
token differs from the sources' is stale and gets rebuilt.
"""
from __future__ import annotations

import contextlib
import fcntl
import hashlib
import math
import os
import shutil
import subprocess
import tempfile
import uuid
import zipfile
from dataclasses import dataclass
from pathlib import Path
from xml.etree import ElementTree as ET

import yaml

from prlpid_fmi.bundled import data_dir, fmu_cache_dir
from prlpid_fmi.errors import ArgumentError, PlantError
from prlpid_fmi.rundir import write_atomic

PLANT_SOURCES = data_dir("plant_sources")
COMMON_SOURCES = ("plant_model.h", "instance.h", "instance.c", "faults.h", "faults.c", "forecast.h", "forecast.c")
API_SOURCE = {1: "fmi1_api.c", 2: "fmi2_api.c", 3: "fmi3_api.c"}
INTERFACES = ("co-simulation", "model-exchange")
DEFAULT_FMI_VERSION = 2
DEFAULT_FIXED_STEP_S = 1e-3  # internal RK4 step of a plant whose model.yaml declares none (bundled plants do)
DEFAULT_EXPERIMENT_STEP_S = 0.1
DEFAULT_EXPERIMENT_STOP_S = 10.0  # DefaultExperiment stopTime (a test build with PRLPID_FAULT_STOP_TIME: that value)
CAPABILITY_FLAGS = ("canGetAndSetFMUstate", "canSerializeFMUstate", "canBeInstantiatedOnlyOncePerProcess")
CAUSALITY_CODES = {
    ("independent", None): "CAUSALITY_INDEPENDENT",
    ("input", None): "CAUSALITY_INPUT",
    ("output", None): "CAUSALITY_OUTPUT",
    ("parameter", "tunable"): "CAUSALITY_TUNABLE_PARAMETER",
    ("parameter", "fixed"): "CAUSALITY_FIXED_PARAMETER",
}


@dataclass(frozen=True)
class Variable:
    """One real variable of a bundled plant; value reference = position in PlantSpec.variables."""

    name: str
    causality: str  # independent | input | output | parameter
    variability: str | None = None  # tunable | fixed for parameters
    start: float | None = None
    unit: str | None = None
    description: str = ""
    min: float | None = None       # declared range and nominal value (written to the modelDescription)
    max: float | None = None
    nominal: float | None = None

    def declared(self) -> dict[str, str]:
        """The min, max and nominal attributes that are set, as modelDescription strings."""
        return {k: _fmt(getattr(self, k)) for k in ("min", "max", "nominal") if getattr(self, k) is not None}


@dataclass(frozen=True)
class PlantSpec:
    """A bundled plant as described by its model.yaml, with the two variables every plant has first."""

    name: str
    description: str
    states: tuple[str, ...]
    variables: tuple[Variable, ...]
    directory: Path


def bundled_plant_names() -> list[str]:
    """Names of the plants in plant_sources/ (every directory with a model.yaml)."""
    if not PLANT_SOURCES.is_dir():
        return []
    return sorted(p.name for p in PLANT_SOURCES.iterdir() if (p / "model.yaml").is_file())


def load_spec(name: str, directory: Path | None = None) -> PlantSpec:
    """Read <directory>/model.yaml (default plant_sources/<name>/). Raises PlantError for an unknown plant."""
    directory = Path(directory) if directory is not None else PLANT_SOURCES / name
    if not (directory / "model.yaml").is_file():
        known = ", ".join(bundled_plant_names()) or "none found"
        raise PlantError(f"unknown bundled plant {name!r}; expected one of: {known} (in {PLANT_SOURCES})")
    raw = yaml.safe_load((directory / "model.yaml").read_text())
    fixed_step = raw.get("fixed_step", DEFAULT_FIXED_STEP_S)
    if isinstance(fixed_step, bool) or not isinstance(fixed_step, (int, float)) or not 0 < fixed_step < math.inf:
        raise PlantError(f"{directory / 'model.yaml'}: fixed_step: must be a positive finite number of seconds "
                         f"(got {fixed_step!r}; expected e.g. 0.01)")
    variables = [
        Variable("time", "independent", description="Simulation time", unit="s"),
        Variable("fixed_step", "parameter", "fixed", float(fixed_step), "s",
                 "Internal fixed RK4 step; each communication step uses ceil(h/fixed_step) sub-steps"),
    ]
    for item in raw["variables"]:
        variables.append(Variable(**item))
    return PlantSpec(raw["name"], raw["description"], tuple(raw["states"]), tuple(variables), directory)


def _fmt(value: float) -> str:
    return repr(float(value))


def variables_header(spec: PlantSpec, token: str) -> str:
    """C header with value references, start values and causalities (sources/variables.h)."""
    lines = [
        f"/* Generated by prlpid_fmi.fmu.build from {spec.name}/model.yaml; do not edit. */",
        "#ifndef VARIABLES_H", "#define VARIABLES_H", "",
        f'#define MODEL_IDENTIFIER_STRING "{spec.name}"',
        f"#define MODEL_IDENTIFIER {spec.name}",
        f'#define INSTANTIATION_TOKEN "{token}"',
        f"#define N_STATES {len(spec.states)}",
        f"#define N_VARIABLES {len(spec.variables)}", "",
        "enum { CAUSALITY_INDEPENDENT, CAUSALITY_INPUT, CAUSALITY_OUTPUT,",
        "       CAUSALITY_TUNABLE_PARAMETER, CAUSALITY_FIXED_PARAMETER };", "",
        "enum {",
    ]
    lines += [f"    VR_{v.name} = {vr}," for vr, v in enumerate(spec.variables)]
    lines += ["};", "", "static const double START_VALUES[N_VARIABLES] = {"]
    lines += [f"    {_fmt(v.start if v.start is not None else 0.0)}, /* {v.name} */" for v in spec.variables]
    lines += ["};", "", "static const unsigned char CAUSALITY[N_VARIABLES] = {"]
    for v in spec.variables:
        key = (v.causality, v.variability if v.causality == "parameter" else None)
        lines.append(f"    {CAUSALITY_CODES[key]}, /* {v.name} */")
    lines += ["};", "", "#endif", ""]
    return "\n".join(lines)


def _source_files(spec: PlantSpec, fmi_version: int) -> list[str]:
    return [*COMMON_SOURCES, API_SOURCE[fmi_version], "model.c", "variables.h"]


def _compiled_sources(spec: PlantSpec, fmi_version: int) -> list[str]:
    return [f for f in _source_files(spec, fmi_version) if f.endswith(".c")]


def instantiation_token(spec: PlantSpec, fmi_version: int, defines: dict | None = None,
                        capabilities: dict | None = None, interface: str = "co-simulation") -> str:
    """Deterministic GUID from the plant's sources, the shared layer, this builder, the interface and any
    test switches."""
    digest = hashlib.sha256(f"fmi{fmi_version}{'' if interface == INTERFACES[0] else interface}".encode())
    if defines or capabilities:
        digest.update(repr((sorted((defines or {}).items()), sorted((capabilities or {}).items()))).encode())
    for path in [*(PLANT_SOURCES / "common" / f for f in (*COMMON_SOURCES, API_SOURCE[fmi_version])),
                 spec.directory / "model.c", spec.directory / "model.yaml", Path(__file__),
                 *sorted(spec.directory.glob("*.mo"))]:
        digest.update(path.read_bytes())
    return "{" + str(uuid.UUID(bytes=digest.digest()[:16])) + "}"


def _units(spec: PlantSpec) -> list[str]:
    return sorted({v.unit for v in spec.variables if v.unit})


def experiment_stop_time(defines: dict | None) -> float:
    """The DefaultExperiment stopTime [s] a build declares: the stop time a PRLPID_FAULT_STOP_TIME test build
    enforces, else DEFAULT_EXPERIMENT_STOP_S."""
    return float((defines or {}).get("PRLPID_FAULT_STOP_TIME", DEFAULT_EXPERIMENT_STOP_S))


def _units_and_experiment(root: ET.Element, spec: PlantSpec, stop_time_s: float = DEFAULT_EXPERIMENT_STOP_S) -> None:
    """UnitDefinitions and DefaultExperiment, the same in FMI 2.0 and 3.0."""
    units = ET.SubElement(root, "UnitDefinitions")
    for u in _units(spec):
        ET.SubElement(units, "Unit", name=u)
    ET.SubElement(root, "DefaultExperiment", startTime="0.0", stopTime=_fmt(stop_time_s),
                  stepSize=_fmt(DEFAULT_EXPERIMENT_STEP_S))


def _capability_attributes(fmi_version: int, capabilities: dict | None) -> dict[str, str]:
    """modelDescription capability flags {FMI 2.0 name: bool} in the version's spelling ("true"/"false")."""
    out = {}
    for name, on in (capabilities or {}).items():
        if name not in CAPABILITY_FLAGS:
            raise ValueError(f"unknown capability flag {name!r}; expected one of {', '.join(CAPABILITY_FLAGS)}")
        out[name.replace("FMUstate", "FMUState") if fmi_version == 3 else name] = "true" if on else "false"
    return out


def _model_description_fmi2(spec: PlantSpec, token: str, capabilities: dict | None = None,
                            interface: str = "co-simulation", api_version: int = 2,
                            stop_time_s: float = DEFAULT_EXPERIMENT_STOP_S) -> ET.Element:
    """FMI 2.0 modelDescription; api_version 1 lists the FMI 1.0 shim as the source to compile (build only)."""
    root = ET.Element("fmiModelDescription", fmiVersion="2.0", modelName=spec.name, guid=token,
                      description=spec.description, generationTool="prlpid-fmi",
                      variableNamingConvention="flat", numberOfEventIndicators="0")
    flags = dict(modelIdentifier=spec.name, canGetAndSetFMUstate="true", canSerializeFMUstate="true",
                 canNotUseMemoryManagementFunctions="true")
    if interface == "model-exchange":
        cs = ET.SubElement(root, "ModelExchange", flags)
    else:
        cs = ET.SubElement(root, "CoSimulation", flags, canHandleVariableCommunicationStepSize="true")
    cs.attrib.update(_capability_attributes(2, capabilities))
    files = ET.SubElement(cs, "SourceFiles")
    for f in _compiled_sources(spec, api_version):
        ET.SubElement(files, "File", name=f)
    _units_and_experiment(root, spec, stop_time_s)
    variables = ET.SubElement(root, "ModelVariables")
    outputs = []
    for vr, v in enumerate(spec.variables):
        attrs = dict(name=v.name, valueReference=str(vr), description=v.description, causality=v.causality)
        real = {}
        if v.causality == "independent":
            attrs["variability"] = "continuous"
        elif v.causality == "parameter":
            attrs.update(variability=v.variability, initial="exact")
            real["start"] = _fmt(v.start)
        elif v.causality == "input":
            real["start"] = _fmt(v.start)
        else:
            attrs["initial"] = "calculated"
            outputs.append(vr + 1)  # 1-based index into ModelVariables
        if v.unit:
            real["unit"] = v.unit
        real.update(v.declared())
        ET.SubElement(ET.SubElement(variables, "ScalarVariable", attrs), "Real", real)
    states, derivatives = _me_state_variables(variables, spec) if interface == "model-exchange" else ([], [])
    structure = ET.SubElement(root, "ModelStructure")
    for tag, indices in (("Outputs", outputs), ("Derivatives", derivatives),
                         ("InitialUnknowns", sorted(outputs + states + derivatives))):
        if indices or tag != "Derivatives":
            element = ET.SubElement(structure, tag)
            for index in indices:
                ET.SubElement(element, "Unknown", index=str(index))
    return root


def _me_state_variables(variables: ET.Element, spec: PlantSpec) -> tuple[list[int], list[int]]:
    """Model exchange: the states and their derivatives after the variables, at the value references
    fmi2_api.c serves them (N_VARIABLES + i, N_VARIABLES + N_STATES + i). Returns their 1-based indices."""
    n, k = len(spec.variables), len(spec.states)
    states = [n + i + 1 for i in range(k)]
    for i, name in enumerate(spec.states):
        ET.SubElement(ET.SubElement(variables, "ScalarVariable", name=f"states.{name}", valueReference=str(n + i),
                                    description=f"continuous state {name}", causality="local",
                                    variability="continuous", initial="calculated"), "Real")
    for i, name in enumerate(spec.states):
        ET.SubElement(ET.SubElement(variables, "ScalarVariable", name=f"der(states.{name})",
                                    valueReference=str(n + k + i), description=f"time derivative of {name}",
                                    causality="local", variability="continuous"), "Real", derivative=str(states[i]))
    return states, [n + k + i + 1 for i in range(k)]


def _model_description_fmi1(spec: PlantSpec, token: str, stop_time_s: float = DEFAULT_EXPERIMENT_STOP_S) -> ET.Element:
    """FMI 1.0 co-simulation stand-alone modelDescription (no time variable; parameters are 'parameter')."""
    root = ET.Element("fmiModelDescription", fmiVersion="1.0", modelName=spec.name, modelIdentifier=spec.name,
                      guid=token, description=spec.description, generationTool="prlpid-fmi",
                      variableNamingConvention="flat", numberOfContinuousStates=str(len(spec.states)),
                      numberOfEventIndicators="0")
    units = ET.SubElement(root, "UnitDefinitions")
    for u in _units(spec):
        ET.SubElement(units, "BaseUnit", unit=u)
    ET.SubElement(root, "DefaultExperiment", startTime="0.0", stopTime=_fmt(stop_time_s))
    variables = ET.SubElement(root, "ModelVariables")
    for vr, v in enumerate(spec.variables):
        if v.causality == "independent":
            continue
        attrs = dict(name=v.name, valueReference=str(vr), description=v.description)
        real = {}
        if v.causality == "parameter":
            attrs.update(variability="parameter", causality="internal")
        else:
            attrs.update(variability="continuous", causality=v.causality)
        if v.causality != "output":
            real["start"] = _fmt(v.start)
        if v.unit:
            real["unit"] = v.unit
        ET.SubElement(ET.SubElement(variables, "ScalarVariable", attrs), "Real", real)
    standalone = ET.SubElement(ET.SubElement(root, "Implementation"), "CoSimulation_StandAlone")
    ET.SubElement(standalone, "Capabilities", canHandleVariableCommunicationStepSize="true",
                  canHandleEvents="true", canRejectSteps="false", canInterpolateInputs="false",
                  maxOutputDerivativeOrder="0", canRunAsynchronuously="false", canSignalEvents="false",
                  canBeInstantiatedOnlyOncePerProcess="false", canNotUseMemoryManagementFunctions="true")
    return root


def _model_description_fmi3(spec: PlantSpec, token: str, capabilities: dict | None = None,
                            stop_time_s: float = DEFAULT_EXPERIMENT_STOP_S) -> ET.Element:
    root = ET.Element("fmiModelDescription", fmiVersion="3.0", modelName=spec.name,
                      instantiationToken=token, description=spec.description,
                      generationTool="prlpid-fmi", variableNamingConvention="flat")
    cs = ET.SubElement(root, "CoSimulation", modelIdentifier=spec.name,
                       canHandleVariableCommunicationStepSize="true", canGetAndSetFMUState="true",
                       canSerializeFMUState="true", hasEventMode="false", providesIntermediateUpdate="false")
    cs.attrib.update(_capability_attributes(3, capabilities))
    _units_and_experiment(root, spec, stop_time_s)
    variables = ET.SubElement(root, "ModelVariables")
    outputs = []
    for vr, v in enumerate(spec.variables):
        attrs = dict(name=v.name, valueReference=str(vr), description=v.description, causality=v.causality)
        if v.causality == "independent":
            attrs["variability"] = "continuous"
        elif v.causality == "parameter":
            attrs.update(variability=v.variability, start=_fmt(v.start))
        elif v.causality == "input":
            attrs["start"] = _fmt(v.start)
        else:
            outputs.append(vr)
        if v.unit:
            attrs["unit"] = v.unit
        attrs.update(v.declared())
        ET.SubElement(variables, "Float64", attrs)
    structure = ET.SubElement(root, "ModelStructure")
    for tag in ("Output", "InitialUnknown"):
        for vr in outputs:
            ET.SubElement(structure, tag, valueReference=str(vr))
    return root


def _build_description_fmi3(spec: PlantSpec) -> ET.Element:
    root = ET.Element("fmiBuildDescription", fmiVersion="3.0")
    config = ET.SubElement(root, "BuildConfiguration", modelIdentifier=spec.name)
    file_set = ET.SubElement(config, "SourceFileSet", language="C99")
    for f in _compiled_sources(spec, 3):
        ET.SubElement(file_set, "SourceFile", name=f)
    return root


def _write_xml(element: ET.Element, path: Path) -> None:
    ET.indent(element)
    ET.ElementTree(element).write(path, encoding="UTF-8", xml_declaration=True)


def fmu_path(name: str, fmi_version: int = DEFAULT_FMI_VERSION, out_dir: Path | None = None,
             interface: str = "co-simulation") -> Path:
    """Where the bundled FMU lives: <out_dir>/<Name>.fmu for FMI 2.0, <out_dir>/fmi3/<Name>.fmu for FMI 3.0,
    <out_dir>/fmi1/<Name>.fmu for FMI 1.0, <out_dir>/me/<Name>.fmu for FMI 2.0 model exchange
    (out_dir default: the per-user FMU cache)."""
    base = Path(out_dir) if out_dir is not None else fmu_cache_dir()
    if interface == "model-exchange":
        return base / "me" / f"{name}.fmu"
    return base / f"{name}.fmu" if fmi_version == 2 else base / f"fmi{fmi_version}" / f"{name}.fmu"


@contextlib.contextmanager
def _build_lock():
    """Serialise builds across processes: an exclusive lock on <FMU cache>/.build.lock."""
    cache = fmu_cache_dir()
    cache.mkdir(parents=True, exist_ok=True)
    with open(cache / ".build.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        yield


def build_fmu(name: str, fmi_version: int = DEFAULT_FMI_VERSION, out_dir: Path | None = None,
              source_dir: Path | None = None, defines: dict | None = None,
              capabilities: dict | None = None, interface: str = "co-simulation",
              binary_name: str | None = None) -> Path:
    """Build one plant into an FMU (binary for this platform + sources). Returns its path.

    out_dir: where to write (default: the per-user FMU cache). source_dir: a directory with model.yaml
    and model.c written like plant_sources/<Name>/ (default: the bundled plant `name`), so a user's own
    C model builds with the same shared FMI layer.
    defines: C preprocessor switches {NAME: value or None}, e.g. the test faults of
    plant_sources/common/faults.h ({"PRLPID_FAULT_NAN_AFTER_S": 3.0}); bundled plants are built without.
    capabilities: modelDescription flags to override {FMI 2.0 name: bool}, names in CAPABILITY_FLAGS.
    interface: "co-simulation" or "model-exchange" (FMI 2.0 only: an FMU with only that interface).
    binary_name: a test FMU whose binary is named this instead of the modelIdentifier (some exporters do that).
    """
    with _build_lock():
        return _build(name, fmi_version, out_dir, source_dir, defines, capabilities, interface, binary_name)


def _build(name: str, fmi_version: int, out_dir: Path | None, source_dir: Path | None,
           defines: dict | None = None, capabilities: dict | None = None, interface: str = "co-simulation",
           binary_name: str | None = None) -> Path:
    if fmi_version not in API_SOURCE:
        raise ArgumentError(f"{{fmi_version}} must be 1, 2 or 3, got {fmi_version!r}")
    if interface not in INTERFACES or (interface == "model-exchange" and fmi_version != 2):
        raise PlantError(f"interface must be one of {', '.join(INTERFACES)} (model exchange with FMI 2.0 only), "
                         f"got {interface!r} with FMI {fmi_version}.0")
    from fmpy.build import build_platform_binary

    spec = load_spec(name, source_dir)
    token = instantiation_token(spec, fmi_version, defines, capabilities, interface)
    stop = experiment_stop_time(defines)
    target = fmu_path(name, fmi_version, out_dir, interface)
    target.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix=f"build-{name}-") as tmp:
        unzipdir = Path(tmp) / "fmu"
        sources = unzipdir / "sources"
        sources.mkdir(parents=True)
        for f in (*COMMON_SOURCES, API_SOURCE[fmi_version]):
            shutil.copy2(PLANT_SOURCES / "common" / f, sources / f)
        shutil.copy2(spec.directory / "model.c", sources / "model.c")
        (sources / "variables.h").write_text(variables_header(spec, token))
        documentation = unzipdir / "documentation"
        documentation.mkdir()
        for mo in spec.directory.glob("*.mo"):
            shutil.copy2(mo, documentation / mo.name)
        if fmi_version in (1, 2):  # FMI 1.0: FMPy's CMake build reads an FMI 2.0 description, replaced below
            _write_xml(_model_description_fmi2(spec, token, capabilities, interface, fmi_version, stop),
                       unzipdir / "modelDescription.xml")
        else:
            _write_xml(_model_description_fmi3(spec, token, capabilities, stop), unzipdir / "modelDescription.xml")
            _write_xml(_build_description_fmi3(spec), sources / "buildDescription.xml")
        build_dir = Path(tmp) / "cmake"
        build_dir.mkdir()
        log = Path(tmp) / "build.log"
        try:
            with open(log, "w") as out:
                _quiet_call(build_platform_binary, unzipdir, build_dir, out, defines)
        except (subprocess.CalledProcessError, OSError) as exc:
            raise PlantError(f"building {name} (FMI {fmi_version}.0) failed: {exc}\n{log.read_text()[-3000:]}") from None
        if fmi_version == 1:
            _write_xml(_model_description_fmi1(spec, token, stop), unzipdir / "modelDescription.xml")
        def write_zip(tmp: Path) -> None:
            with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as zf:
                for path in sorted(unzipdir.rglob("*")):
                    if path.is_file():
                        member = path.relative_to(unzipdir).as_posix()
                        if binary_name and member.startswith("binaries/") and path.stem == spec.name:
                            member = member.rsplit("/", 1)[0] + f"/{binary_name}{path.suffix}"
                        zf.write(path, member)

        write_atomic(target, write_zip)
    return target


def _cmake_options(defines: dict | None = None) -> dict[str, str]:
    """No fused multiply-add: the C forecast must round exactly like Python's float arithmetic.

    GCC contracts a*b + c into an FMA by default in GNU C modes, clang in any mode, wherever the
    target has FMA (aarch64, x86-64-v3). MSVC does not contract under its default /fp:precise.
    defines {NAME: value or None} become -DNAME[=value] (/D on MSVC).
    """
    flags = [] if os.name == "nt" else ["-ffp-contract=off"]
    for key, value in (defines or {}).items():
        flags.append(("/D" if os.name == "nt" else "-D") + (key if value is None else f"{key}={value}"))
    return {"CMAKE_C_FLAGS:STRING": " ".join(flags)} if flags else {}


def _quiet_call(build, unzipdir: Path, build_dir: Path, out, defines: dict | None = None) -> None:
    """Run FMPy's CMake build with the compiler's output sent to `out` instead of the terminal."""
    saved = os.dup(1), os.dup(2)
    try:
        os.dup2(out.fileno(), 1)
        os.dup2(out.fileno(), 2)
        build(unzipdir, build_dir=build_dir, cmake_options=_cmake_options(defines))
    finally:
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        os.close(saved[0])
        os.close(saved[1])


def is_current(name: str, fmi_version: int = DEFAULT_FMI_VERSION, out_dir: Path | None = None,
               interface: str = "co-simulation") -> bool:
    """True when the FMU exists and was built from the current sources (same instantiation token). The answer is
    remembered for the process while neither the FMU nor a source file changes size or time (reading the token costs
    milliseconds; a tune asks before every simulation)."""
    path = fmu_path(name, fmi_version, out_dir, interface)
    if not path.is_file():
        return False
    directory = PLANT_SOURCES / name
    files = [path, Path(__file__), *(PLANT_SOURCES / "common" / f for f in (*COMMON_SOURCES, API_SOURCE[fmi_version])),
             *sorted(directory.glob("*"))]
    signature = tuple((str(f), f.stat().st_size, f.stat().st_mtime_ns) for f in files if f.is_file())
    key = (name, fmi_version, interface, signature)
    if key not in _CURRENT:
        if len(_CURRENT) >= 256:
            _CURRENT.clear()
        _CURRENT[key] = _token_matches(path, name, fmi_version, interface)
    return _CURRENT[key]


_CURRENT: dict = {}  # is_current's answers, keyed by the plant, the FMI version and its files' sizes and times


def _token_matches(path: Path, name: str, fmi_version: int, interface: str) -> bool:
    """The FMU at `path` carries the instantiation token of the current sources."""
    try:
        with zipfile.ZipFile(path) as zf:
            root = ET.fromstring(zf.read("modelDescription.xml"))
    except (zipfile.BadZipFile, KeyError, ET.ParseError):
        return False
    token = root.get("instantiationToken") if fmi_version == 3 else root.get("guid")
    return token == instantiation_token(load_spec(name), fmi_version, interface=interface)


def bundled_fmu(name: str, fmi_version: int = DEFAULT_FMI_VERSION, out_dir: Path | None = None,
                interface: str = "co-simulation") -> Path:
    """Path of a bundled plant's FMU, built first when it is missing or older than its sources.

    Safe to call from several processes at once (a file lock in the FMU cache serialises the builds).
    """
    if not is_current(name, fmi_version, out_dir, interface):
        with _build_lock():
            if not is_current(name, fmi_version, out_dir, interface):
                _build(name, fmi_version, out_dir, None, interface=interface)
    return fmu_path(name, fmi_version, out_dir, interface)


def build_all(fmi_version: int = DEFAULT_FMI_VERSION, out_dir: Path | None = None) -> list[Path]:
    """Rebuild every bundled plant. Returns the FMU paths."""
    return [build_fmu(name, fmi_version, out_dir) for name in bundled_plant_names()]
