"""Every benchmark script imports against the code as it is now.

``make bench`` is run by hand, not by CI: a name a change removed from the code would otherwise
surface only there, minutes into a run. Importing runs each script's imports and definitions
(no ``main``).
"""

import subprocess
import sys
from pathlib import Path

BENCHMARKS = Path(__file__).resolve().parents[2] / "benchmarks"
IMPORT_ALL = """
import importlib, sys
failed = []
for name in sys.argv[1:]:
    try:
        importlib.import_module(name)
    except Exception as err:
        failed.append(f"{name}: {err!r}")
print("\\n".join(failed))
"""


def test_every_benchmark_script_imports() -> None:
    names = sorted(path.stem for path in BENCHMARKS.glob("*.py"))
    assert "floor_ratio" in names
    out = subprocess.run(
        [sys.executable, "-c", IMPORT_ALL, *names],
        cwd=BENCHMARKS,
        capture_output=True,
        text=True,
        check=True,
        timeout=120,
    )
    assert out.stdout.strip() == "", out.stdout
