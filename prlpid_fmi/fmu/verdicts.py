"""What running an FMU taught the tool about it (does its reset reset? does it need a stop time?),
remembered per FMU file across runs: a small JSON file in the per-user cache folder, keyed by the
SHA-256 of the FMU file, written atomically (a temporary file, then a rename). A lost or damaged
file only means the FMU is checked again."""
from __future__ import annotations

import hashlib
import json
from pathlib import Path

FILE_NAME = "fmu_verdicts.json"
_hashes: dict[tuple, str] = {}
_memory: dict[str, dict] = {}   # this process's verdicts, also when the cache file cannot be written


def cache_file() -> Path:
    """The verdict file: <per-user cache>/prlpid-fmi/<version>/fmu_verdicts.json."""
    from platformdirs import user_cache_path

    from prlpid_fmi.version import __version__

    return user_cache_path("prlpid-fmi", appauthor=False, version=__version__) / FILE_NAME


def fmu_hash(path: str | Path) -> str:
    """SHA-256 of the FMU file (hex), computed once per (path, size, mtime) in a process."""
    p = Path(path)
    st = p.stat()
    key = (str(p.resolve()), st.st_size, st.st_mtime_ns)
    if key not in _hashes:
        digest = hashlib.sha256()
        with open(p, "rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                digest.update(block)
        _hashes[key] = digest.hexdigest()
    return _hashes[key]


def _read() -> dict:
    try:
        data = json.loads(cache_file().read_text())
        return data if isinstance(data, dict) else {}
    except (OSError, ValueError):
        return {}


def get(path: str | Path, key: str):
    """The verdict `key` remembered for this FMU file, or None."""
    h = fmu_hash(path)
    if key in _memory.get(h, {}):
        return _memory[h][key]
    value = _read().get(h, {}).get(key)
    if value is not None:
        _memory.setdefault(h, {})[key] = value
    return value


def put(path: str | Path, key: str, value) -> None:
    """Remember verdict `key` = value (JSON) for this FMU file; an unwritable cache is not an error."""
    from prlpid_fmi.rundir import write_atomic

    h = fmu_hash(path)
    _memory.setdefault(h, {})[key] = value
    data = _read()
    entry = data.setdefault(h, {})
    entry.update({key: value, "file": Path(path).name})
    try:
        write_atomic(cache_file(), json.dumps(data, indent=1, sort_keys=True))
    except OSError:
        pass
