"""The house as tools see it: every ``wallmap`` import resolves statically, layers hold, functions
are short.

The user's layout keeps ``common/`` and ``services/`` at the top of the checkout; the package
reaches them through the links ``wallmap/common`` and ``wallmap/services``, and the editable
install is a plain path (no import hook), so an IDE's go-to-definition and a static analyser
follow every import. basedpyright runs here with type checking off and only unresolved imports
as errors, on every import statement of the package.
"""

from __future__ import annotations

import ast
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import ROOT


def _imports(path: Path) -> list[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"))
    names = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names += [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.append(node.module)
    return names


def test_the_package_links_to_the_users_layout() -> None:
    for name in ("common", "services"):
        link = ROOT / "wallmap" / name
        assert link.is_symlink()
        assert link.resolve() == (ROOT / name).resolve()


def test_common_imports_nothing_above_it() -> None:
    """The maths and the plumbing under everything: no service, no command, no tool."""
    offenders = {
        f"{path.relative_to(ROOT)}: {name}"
        for path in (ROOT / "common").rglob("*.py")
        for name in _imports(path)
        if name.startswith("wallmap.") and not name.startswith("wallmap.common")
    }
    assert not offenders, sorted(offenders)


def test_services_import_no_command_or_tool() -> None:
    offenders = {
        f"{path.relative_to(ROOT)}: {name}"
        for path in (ROOT / "services").rglob("*.py")
        for name in _imports(path)
        if name.startswith("wallmap.")
        and not name.startswith(("wallmap.common", "wallmap.services"))
    }
    assert not offenders, sorted(offenders)


# The Zenoh layer of common/: sessions and keys, delivery, the service runtime, map requests.
ZENOH_LAYER = {"transport", "delivery", "runtime", "map_requests"}
PURE = (
    "wallmap.services.pipeline",  # the method, top to bottom
    "wallmap.offline",  # the offline runner
    "wallmap.config",  # the one configuration
    "wallmap.services.mapper.intake",
    "wallmap.services.mapper.restore",
)


def test_the_pure_core_loads_no_zenoh_and_no_terminal() -> None:
    """The maths, the pipeline, the offline runner and the mapper's policy import without Zenoh
    (or termios): where it is not installed, or not wanted, they still run."""
    maths = [
        f"wallmap.common.{path.stem}"
        for path in sorted((ROOT / "common").glob("*.py"))
        if path.stem not in ZENOH_LAYER | {"__init__"}
    ]
    code = (
        "import importlib, sys\n"
        f"for name in {[*maths, *PURE]!r}: importlib.import_module(name)\n"
        "print(sorted({m.split('.')[0] for m in sys.modules} & {'zenoh', 'termios'}))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT
    )
    assert out.stdout.strip() == "[]", out.stdout


# What a service's process must not load: another command's modules (or the bag reader's), which
# the command line importing every command at its top made each service pay for as it started.
NOT_LOADED_BY = {
    "mapper": ("rosbags.rosbag1", "wallmap.services.player.service", "wallmap.doctor_inspect"),
    "detector": ("rosbags", "wallmap.services.mapper.service", "wallmap.view.server"),
    "router": ("rosbags", "wallmap.services.detector.service", "wallmap.services.mapper.service"),
}


@pytest.mark.parametrize("command", sorted(NOT_LOADED_BY))
def test_a_services_command_loads_its_own_modules_only(command: str) -> None:
    """The command line and the service's own module, as ``wallmap COMMAND`` imports them."""
    own = "" if command == "router" else f"import wallmap.services.{command}.service\n"
    code = (
        "import sys\nfrom wallmap.cli import build_parser\nbuild_parser()\n"
        f"{own}print(sorted(m for m in {NOT_LOADED_BY[command]!r} if m in sys.modules))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT
    )
    assert out.stdout.strip() == "[]", out.stdout


def _import_statements(path: Path) -> set[str]:
    """Every absolute import statement of a file, one name each (``from a import b``)."""
    lines = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            lines |= {f"import {alias.name}" for alias in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module != "__future__":
            lines |= {f"from {node.module} import {alias.name}" for alias in node.names}
    return lines


def test_a_static_analyser_resolves_every_import(tmp_path: Path) -> None:
    """Every import statement of the package, gathered in one file the analyser checks.

    Checking the package's 170 files themselves takes it 40 s with type checking off; which
    imports resolve is the same from any file, as every one is absolute.
    """
    exe = shutil.which("basedpyright", path=str(Path(sys.executable).parent))
    if exe is None:
        pytest.fail("basedpyright is missing: install the dev extra (make test does)")
    sources = [f for name in ("common", "services", "wallmap") for f in (ROOT / name).rglob("*.py")]
    statements = sorted(set().union(*map(_import_statements, sources)))
    gathered = tmp_path / "every_import.py"
    lines = [*statements, "import wallmap.common.no_such_module"]  # planted: it must be reported
    gathered.write_text("\n".join(lines) + "\n")
    config = {
        "include": [str(gathered)],
        "typeCheckingMode": "off",
        "reportMissingImports": "error",
        "venvPath": str(Path(sys.prefix).parent),
        "venv": Path(sys.prefix).name,
    }
    (tmp_path / "pyrightconfig.json").write_text(json.dumps(config))
    done = subprocess.run(
        [exe, "-p", str(tmp_path / "pyrightconfig.json"), "--outputjson"],
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
    )
    report = json.loads(done.stdout)
    unresolved = [
        lines[d["range"]["start"]["line"]]
        for d in report["generalDiagnostics"]
        if d.get("rule") == "reportMissingImports"
    ]
    assert len(statements) > 300
    assert unresolved == [lines[-1]], unresolved
    assert report["summary"]["errorCount"] == 1, report["generalDiagnostics"][:5]


def test_configuration_classes_are_named_config_or_settings() -> None:
    """``…Config`` tunes an algorithm, ``…Settings`` says how a service runs (architecture.md):
    no third word for the same thing."""
    others = sorted(
        f"{path.relative_to(ROOT)} {node.name}"
        for folder in ("common", "services", "wallmap")
        for path in (ROOT / folder).rglob("*.py")
        if path.relative_to(ROOT).parts[1:2] not in (("common",), ("services",))  # the links
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8")))
        if isinstance(node, ast.ClassDef)
        and node.name.endswith(("Params", "Parameters", "Options", "Conf", "Setup", "Tuning"))
    )
    assert not others, others


def test_no_function_is_longer_than_60_lines() -> None:
    """Readable top to bottom: a function that does not fit on a screen does several jobs.

    Over the pure code, the services and the command (``wallmap/``).
    """
    found = {
        f"{path.relative_to(ROOT)} {node.name}": node.end_lineno - node.lineno + 1
        for folder in ("common", "services", "wallmap")
        for path in (ROOT / folder).rglob("*.py")
        if path.relative_to(ROOT).parts[1:2] not in (("common",), ("services",))  # the links
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8")))
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef)
    }
    long = sorted(f"{name} ({n})" for name, n in found.items() if n > 60)
    assert not long, long


def test_a_checkout_without_its_links_says_so_at_import(tmp_path: Path) -> None:
    """A clone where git made no symbolic links has text files for wallmap/common and
    wallmap/services: ``import wallmap`` says what happened and what to do, in one error."""
    package = tmp_path / "wallmap"
    package.mkdir()
    (package / "__init__.py").write_text((ROOT / "wallmap" / "__init__.py").read_text())
    (package / "common").write_text("../common")  # what git writes for a link it cannot make
    (package / "services").write_text("../services")
    done = subprocess.run(
        [sys.executable, "-c", "import wallmap"],
        cwd=tmp_path,
        env={"PATH": os.environ.get("PATH", ""), "PYTHONPATH": str(tmp_path)},
        capture_output=True,
        text=True,
        check=False,
    )
    assert done.returncode == 1
    last = done.stderr.strip().splitlines()[-1]
    assert last.startswith("ImportError: wallmap/common is not a folder"), done.stderr
    assert "core.symlinks=true" in last
