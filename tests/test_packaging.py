"""A regular (non-editable) install works from any folder: the wheel carries the plant sources and the
bundled scenarios, FMUs are built into the per-user cache, and nothing is written into site-packages.

The wheel is built from a copy of the project's files and installed into a fresh venv that reuses this
environment's dependencies through a .pth file (no downloads).
"""
import os
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest
import yaml

import prlpid_fmi

REPO = Path(__file__).resolve().parents[1]
PROJECT_FILES = ("pyproject.toml", "setup.py", "MANIFEST.in", "README.md", "prlpid_fmi", "plant_sources", "scenarios")
PLANT_SUFFIXES = {".c", ".h", ".yaml", ".mo"}
IGNORE = shutil.ignore_patterns("__pycache__", "*.pyc", "*.egg-info", "build")


def _run(argv, **kwargs) -> subprocess.CompletedProcess:
    proc = subprocess.run([str(a) for a in argv], capture_output=True, text=True, **kwargs)
    assert proc.returncode == 0, f"{argv}\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
    return proc


def _copy_project(dst: Path) -> Path:
    dst.mkdir()
    for name in PROJECT_FILES:
        src = REPO / name
        if src.is_dir():
            shutil.copytree(src, dst / name, ignore=IGNORE)
        else:
            shutil.copy2(src, dst / name)
    return dst


def _venv(path: Path) -> Path:
    """A venv without pip whose interpreter also sees this environment's packages (appended to sys.path)."""
    _run([sys.executable, "-m", "venv", "--without-pip", path])
    python = path / "bin" / "python"
    purelib = Path(_run([python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"]).stdout.strip())
    ours = {sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]}
    (purelib / "_prlpid_test_parent_env.pth").write_text("\n".join(sorted(ours)) + "\n")
    return python


def _files(folder: Path) -> dict[str, int]:
    return {str(p.relative_to(folder)): p.stat().st_mtime_ns for p in folder.rglob("*") if p.is_file()}


def _clean_env(**extra) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    env.update(extra)
    return env


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    base = tmp_path_factory.mktemp("wheel")
    src = _copy_project(base / "src")
    _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "--no-index", "-q",
          "-w", base / "dist", src])
    (whl,) = (base / "dist").glob("prlpid_fmi-*.whl")
    return whl


def test_wheel_holds_every_module_plant_source_and_scenario(wheel):
    names = set(zipfile.ZipFile(wheel).namelist())
    modules = {p.relative_to(REPO).as_posix() for p in (REPO / "prlpid_fmi").rglob("*.py")}
    plants = {"prlpid_fmi/" + p.relative_to(REPO).as_posix() for p in (REPO / "plant_sources").rglob("*")
              if p.suffix in PLANT_SUFFIXES}
    scenarios = {"prlpid_fmi/" + p.relative_to(REPO).as_posix() for p in (REPO / "scenarios").iterdir()
                 if p.suffix in (".yaml", ".json")}  # the scenarios and the JSON Schema editors read
    assert {"prlpid_fmi/plant_sources/common/instance.c", "prlpid_fmi/scenarios/first_order.yaml"} <= plants | scenarios
    templates = {p.relative_to(REPO).as_posix() for p in (REPO / "prlpid_fmi" / "export" / "templates").rglob("*.j2")}
    assert modules <= names and plants <= names and scenarios <= names and templates and templates <= names
    assert not [n for n in names if n.startswith(("fmus/", "tests/")) or n.endswith((".fmu", ".pyc"))]
    version = wheel.name.split("-")[1]
    assert version == prlpid_fmi.__version__


def test_wheel_install_works_from_any_folder(wheel, tmp_path):
    python = _venv(tmp_path / "venv")
    _run([python, "-m", "pip", "install", "-q", "--no-deps", "--no-index", "--ignore-installed", wheel])
    site = Path(_run([python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"]).stdout.strip())
    cli = tmp_path / "venv" / "bin" / "prlpid-fmi"
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    cache = tmp_path / "cache"
    env = _clean_env(XDG_CACHE_HOME=str(cache))
    where = _run([python, "-c", "import prlpid_fmi.bundled as b; print(b.__file__); print(b.fmu_cache_dir())"],
                 cwd=elsewhere, env=env).stdout.split()
    assert Path(where[0]).is_relative_to(site) and Path(where[1]).is_relative_to(cache)
    site_before, parent_before = _files(site), _files(Path(sysconfig.get_paths()["purelib"]))

    built = _run([cli, "build-fmus"], cwd=elsewhere, env=env).stdout.splitlines()
    plants = sorted(p.name for p in (REPO / "plant_sources").iterdir() if (p / "model.yaml").is_file())
    fmu_dir = Path(where[1])
    assert built == [f"built {fmu_dir / f'{name}.fmu'}" for name in plants]
    assert (fmu_dir / ".build.lock").is_file()

    # the bundled scenario by name resolves to the wheel's copy
    wheel_scenario = site / "prlpid_fmi" / "scenarios" / "first_order.yaml"
    validated = _run([cli, "validate", "first_order"], cwd=elsewhere, env=env).stdout
    assert validated.startswith(f"{wheel_scenario}: ok")
    # the main job from the wheel: that scenario with its bundled plant (by name, built from the wheel's sources), a
    # token fixed-PID search (what this checks is the install; the search has tests of its own); written outside
    # `elsewhere`, which must stay empty
    doc = yaml.safe_load(wheel_scenario.read_text())
    assert doc["plant"]["fmu"] == "FirstOrderUnstable"
    doc["baseline"] = {**doc.get("baseline", {}), "episodes": 1, "maxiter": 1, "popsize": 2}
    scenario = tmp_path / "scenario" / "first_order.yaml"
    scenario.parent.mkdir()
    scenario.write_text(yaml.safe_dump(doc, sort_keys=False))
    run = tmp_path / "run"
    proc = _run([cli, "tune", scenario, "--timesteps", "2048", "--out", run], cwd=elsewhere, env=env)
    assert f"run directory: {run}" in proc.stdout
    for name in ("model.zip", "metrics.json", "report.md", "gains.csv", "response.png", "fixed_pid.json"):
        assert (run / name).is_file(), name
    assert f"Scenario file: `{scenario}`" in (run / "report.md").read_text()

    assert _files(site) == site_before, "the tool wrote into the venv's site-packages"
    assert _files(Path(sysconfig.get_paths()["purelib"])) == parent_before
    assert sorted(p.name for p in elsewhere.iterdir()) == []


def test_nothing_to_do_is_one_line(wheel, tmp_path):
    """A broken install without plant sources: build-fmus and check-plants say so and exit 2."""
    python = _venv(tmp_path / "venv")
    _run([python, "-m", "pip", "install", "-q", "--no-deps", "--no-index", "--ignore-installed", wheel])
    site = Path(_run([python, "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"]).stdout.strip())
    shutil.rmtree(site / "prlpid_fmi" / "plant_sources")
    for command in ("build-fmus", "check-plants"):
        proc = subprocess.run([tmp_path / "venv" / "bin" / "prlpid-fmi", command], capture_output=True, text=True,
                              cwd=tmp_path, env=_clean_env(XDG_CACHE_HOME=str(tmp_path / "cache")))
        assert proc.returncode == 2 and "Traceback" not in proc.stderr
        assert len(proc.stderr.strip().splitlines()) == 1 and "no bundled plant sources found" in proc.stderr


def test_editable_install_reads_the_checkouts_folders(tmp_path):
    src = _copy_project(tmp_path / "src")
    python = _venv(tmp_path / "venv")
    _run([python, "-m", "pip", "install", "-q", "--no-deps", "--no-index", "--no-build-isolation",
          "--ignore-installed", "-e", src])
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    env = _clean_env(XDG_CACHE_HOME=str(tmp_path / "cache"))
    out = _run([python, "-c", "from prlpid_fmi.bundled import SCENARIO_DIR; from prlpid_fmi.fmu.build import "
                              "PLANT_SOURCES; print(SCENARIO_DIR); print(PLANT_SOURCES)"], cwd=elsewhere, env=env)
    assert out.stdout.split() == [str(src / "scenarios"), str(src / "plant_sources")]
    proc = _run([tmp_path / "venv" / "bin" / "prlpid-fmi", "validate", "two_tank"], cwd=elsewhere, env=env)
    assert proc.stdout.startswith(f"{src / 'scenarios' / 'two_tank.yaml'}: ok: two_tank")
