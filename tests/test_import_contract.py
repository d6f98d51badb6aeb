"""The import contract of pyproject.toml ([tool.importlinter]) holds: the package layering of
docs/interfaces.md and no import cycle inside a package, imports inside functions counted."""
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def test_import_contract_is_kept():
    exe = shutil.which("lint-imports")
    if exe is None:
        pytest.skip("import-linter is not installed (pip install -e '.[test]')")
    r = subprocess.run([exe, "--no-cache"], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stdout[-3000:] + r.stderr[-2000:]
    assert "Contracts: 2 kept, 0 broken." in r.stdout


def test_a_new_cycle_breaks_the_contract(tmp_path):
    """The contract can fail: a copy of the contract over two packages of which one imports the other
    back inside a function is broken."""
    exe = shutil.which("lint-imports")
    if exe is None:
        pytest.skip("import-linter is not installed")
    pkg = tmp_path / "demo"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from demo import b\n")
    (pkg / "b.py").write_text("def f():\n    from demo import a\n    return a\n")
    cfg = tmp_path / "contract.toml"
    cfg.write_text('[tool.importlinter]\nroot_packages = ["demo"]\n\n[[tool.importlinter.contracts]]\n'
                   'name = "acyclic"\ntype = "acyclic_siblings"\nancestors = ["demo"]\n')
    r = subprocess.run([exe, "--no-cache", str(cfg)], cwd=tmp_path, capture_output=True, text=True, timeout=120,
                       env={"PYTHONPATH": str(tmp_path), "PATH": str(Path(sys.executable).parent) + ":/usr/bin:/bin"})
    assert r.returncode == 1 and "BROKEN" in r.stdout, r.stdout + r.stderr
