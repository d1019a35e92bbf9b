"""The package layout: layers and no import cycles (import-linter, contracts in pyproject.toml), no module using
another module's private names, nothing importing the package root, a small root, and a light `import prlpid_fmi`.

Each checker is also run on a small package written here with the defect it looks for, so a checker that
cannot fail would fail these tests.
"""
from __future__ import annotations

import ast
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGE = REPO / "prlpid_fmi"
MAX_ROOT_MODULES = 12


def _lint(config: Path, cwd: Path) -> tuple[int, str]:
    """import-linter on `config` in a fresh interpreter (its import graph and caches stay out of this one)."""
    proc = subprocess.run([sys.executable, "-c", "import sys; from importlinter.cli import lint_imports; "
                                                 "sys.exit(lint_imports(config_filename=sys.argv[1], no_cache=True))",
                           str(config)], cwd=cwd, capture_output=True, text=True,
                          env={"PYTHONPATH": str(cwd), "PATH": "/usr/bin:/bin"})
    return proc.returncode, proc.stdout + proc.stderr


def _module_name(path: Path, root: Path) -> str:
    parts = list(path.relative_to(root.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def private_imports(root: Path) -> list[str]:
    """`from a import _name` and `a._name` (a: another module of the package, bound by an import) in `root`."""
    package = root.name
    found = []
    for path in sorted(root.rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        me = _module_name(path, root)
        aliases = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.module and node.level == 0 \
                    and node.module.split(".")[0] == package and node.module != me:
                for a in node.names:
                    if a.name.startswith("_") and not a.name.startswith("__"):
                        found.append(f"{path.relative_to(root.parent)}:{node.lineno}: {node.module}.{a.name}")
                    elif (root.parent / node.module.replace(".", "/") / f"{a.name}.py").is_file():
                        aliases.add(a.asname or a.name)  # a module object
            elif isinstance(node, ast.ImportFrom) and node.level:
                found.append(f"{path.relative_to(root.parent)}:{node.lineno}: relative import (absolute expected)")
            elif isinstance(node, ast.Import):
                aliases.update(a.asname for a in node.names if a.asname and a.name.split(".")[0] == package)
        for node in ast.walk(tree):
            if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in aliases \
                    and node.attr.startswith("_") and not node.attr.startswith("__"):
                found.append(f"{path.relative_to(root.parent)}:{node.lineno}: {node.value.id}.{node.attr}")
    return found


def root_imports(root: Path) -> list[str]:
    """Imports of the package root (its __init__) from inside the package: `import pkg`, `from pkg import name`
    where name is not a submodule."""
    package = root.name
    found = []
    for path in sorted(root.rglob("*.py")):
        if path.parent == root and path.name == "__init__.py":
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import) and any(a.name == package for a in node.names):
                found.append(f"{path.relative_to(root.parent)}:{node.lineno}: import {package}")
            elif isinstance(node, ast.ImportFrom) and node.module == package and node.level == 0:
                for a in node.names:
                    if not ((root / f"{a.name}.py").is_file() or (root / a.name / "__init__.py").is_file()):
                        found.append(f"{path.relative_to(root.parent)}:{node.lineno}: from {package} import {a.name}")
    return found


def root_modules(root: Path) -> list[str]:
    return sorted(p.name for p in root.glob("*.py") if p.name != "__init__.py")


# -- the package -------------------------------------------------------------------------------------
def test_the_layer_and_cycle_contracts_hold():
    code, out = _lint(REPO / "pyproject.toml", REPO)
    assert code == 0 and "2 kept, 0 broken" in out, out


def test_no_module_uses_another_modules_private_names():
    assert private_imports(PACKAGE) == []


def test_nothing_inside_the_package_imports_its_root():
    assert root_imports(PACKAGE) == []


def test_the_package_root_holds_few_modules():
    modules = root_modules(PACKAGE)
    assert len(modules) <= MAX_ROOT_MODULES, modules


def test_every_module_opens_with_a_docstring_that_says_its_job():
    missing = [str(p.relative_to(REPO)) for p in sorted(PACKAGE.rglob("*.py"))
               if not ast.get_docstring(ast.parse(p.read_text(encoding="utf-8")))]
    assert missing == []


def test_import_prlpid_fmi_is_light_and_its_api_resolves():
    code = ("import sys, prlpid_fmi; assert 'torch' not in sys.modules and 'stable_baselines3' not in sys.modules; "
            "names = [n for n in prlpid_fmi.__all__ if getattr(prlpid_fmi, n) is None]; print(names)")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO)
    assert proc.returncode == 0 and proc.stdout.strip() == "[]", proc.stderr
    import prlpid_fmi

    with pytest.raises(AttributeError, match="no attribute 'not_there'"):
        prlpid_fmi.not_there  # noqa: B018


# -- the checkers find what they look for ------------------------------------------------------------
def _write(root: Path, files: dict[str, str]) -> None:
    for name, text in files.items():
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(textwrap.dedent(text))


def test_the_checkers_report_a_cycle_an_upward_import_a_private_name_and_a_root_import(tmp_path):
    pkg = tmp_path / "demo"
    _write(pkg, {
        "__init__.py": "", "version.py": "V = 1\n",
        "low/__init__.py": "", "low/a.py": "from demo.low.b import f\n_hidden = 1\n",
        "low/b.py": "def f():\n    from demo.low.a import _hidden\n    return _hidden\n",
        "high/__init__.py": "", "high/c.py": "from demo import version\nimport demo\n",
        "low/d.py": "from demo.high.c import x\n",
    })
    config = tmp_path / "contracts.toml"
    config.write_text(textwrap.dedent("""
        [tool.importlinter]
        root_package = "demo"
        [[tool.importlinter.contracts]]
        name = "layers"
        type = "layers"
        containers = ["demo"]
        layers = ["high", "low", "version"]
        [[tool.importlinter.contracts]]
        name = "acyclic"
        type = "acyclic_siblings"
        ancestors = ["demo"]
    """))
    code, out = _lint(config, tmp_path)
    assert code != 0 and "0 kept, 2 broken" in out, out
    assert private_imports(pkg) == ["demo/low/b.py:2: demo.low.a._hidden"]
    assert root_imports(pkg) == ["demo/high/c.py:2: import demo"]  # `from demo import version` is a submodule
