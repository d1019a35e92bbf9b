"""Is a .fmu archive safe and usable here? Checked before anything is extracted or loaded.

``archive_problems(path)`` returns short problems (empty when fine): not a ZIP archive, member names
FMPy refuses to extract (absolute, with a drive letter, with ``..``, with backslashes), no or an
unreadable modelDescription.xml, and no binary for this platform (binaries/<platform>/<modelIdentifier>
with FMPy's platform names: linux64 for FMI 1.0/2.0, x86_64-linux for FMI 3.0).
"""
from __future__ import annotations

import zipfile
from functools import lru_cache
from pathlib import Path, PurePosixPath


def _unsafe(name: str) -> str | None:
    if "\\" in name:
        return "a backslash"
    if name.startswith("/") or ":" in name:
        return "an absolute path"
    if ".." in PurePosixPath(name).parts:
        return "'..'"
    return None


def archive_problems(path: str | Path) -> list[str]:
    """Problems of the FMU archive at `path`, each a short phrase; [] when it can be extracted and run here.

    Cached per file, modification time and size."""
    p = Path(path).resolve()
    st = p.stat()
    return list(_problems(str(p), st.st_mtime_ns, st.st_size))


@lru_cache(maxsize=64)
def _problems(file: str, mtime_ns: int, size: int) -> tuple[str, ...]:
    return tuple(_check(Path(file)))


def _check(path: Path) -> list[str]:
    import fmpy
    from fmpy import read_model_description

    if not zipfile.is_zipfile(path):
        return ["not a ZIP archive (an FMU is a ZIP file)"]
    try:
        with zipfile.ZipFile(path) as zf:
            names = zf.namelist()
            broken = zf.testzip()
    except (zipfile.BadZipFile, OSError, EOFError, RuntimeError, ValueError) as exc:
        return [f"unreadable ZIP archive: {exc}"]
    problems = []
    if broken is not None:
        problems.append(f"corrupt archive member {broken!r}")
    for name in names:
        why = _unsafe(name)
        if why:
            problems.append(f"unsafe member name {name!r} ({why}; FMPy refuses to extract it)")
            break
    if "modelDescription.xml" not in names:
        return problems + ["no modelDescription.xml in the archive"]
    try:
        md = read_model_description(str(path), validate=False)
    except Exception as exc:  # FMPy raises plain Exceptions (and lxml errors) for a bad description
        text = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        return problems + [f"unreadable modelDescription.xml: {text}"]
    identifiers = [i.modelIdentifier for i in (md.coSimulation, md.modelExchange) if i is not None]
    if not identifiers:
        return problems + ["modelDescription.xml declares neither co-simulation nor model exchange"]
    platform = fmpy.platform_tuple if md.fmiVersion.startswith("3") else fmpy.platform
    wanted = {f"binaries/{platform}/{i}{fmpy.sharedLibraryExtension}" for i in identifiers}
    if not wanted & set(names):
        problems.append(f"no binary for this platform ({sorted(wanted)[0]} is missing; "
                        f"{missing_binary_hint(path.name, names, platform, identifiers[0], fmpy.sharedLibraryExtension)})")
    return problems


def missing_binary_hint(fmu_name: str, names: list[str], platform: str, identifier: str, extension: str) -> str:
    """What to do when binaries/<platform>/<identifier><extension> is not in the archive (member `names`): rename
    the one library there that is named otherwise; compile the C sources when there are some; else which
    platforms the FMU has binaries for."""
    folder = f"binaries/{platform}/"
    others = sorted(n for n in names if n.startswith(folder) and n.endswith(extension) and n.count("/") == 2)
    if len(others) == 1:
        return (f"its binary is named {others[0].rsplit('/', 1)[1]}, not after the modelIdentifier: rename "
                f"{others[0]} to {folder}{identifier}{extension} in the archive")
    if others:
        return (f"{folder} holds {', '.join(n.rsplit('/', 1)[1] for n in others)}, none named after the "
                f"modelIdentifier {identifier!r}: rename the model's library to {identifier}{extension}")
    if any(n.startswith("sources/") and n.endswith((".c", ".cpp")) for n in names):
        return f"it has C sources in sources/: compile them with `fmpy compile {fmu_name}`"
    present = sorted({n.split("/")[1] for n in names  # files, not folder entries: an empty folder has no binary
                      if n.startswith("binaries/") and n.count("/") >= 2 and not n.endswith("/")})
    return f"binaries for: {', '.join(present) or 'no platform'}"


def binary_problem(path: str | Path) -> str:
    """The archive's missing-binary problem (with its hint), or "" (for an FMU that failed to load)."""
    try:
        found = [q for q in archive_problems(path) if q.startswith("no binary")]
    except OSError:
        return ""
    return found[0] if found else ""
