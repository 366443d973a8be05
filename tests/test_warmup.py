"""monoplane.warmup (run by setup.sh) reaches every numba kernel of the package, so that the
first run after setup compiles nothing."""

import re
import subprocess
import sys
from pathlib import Path

import monoplane
from monoplane.warmup import kernel_modules, package_kernels

PACKAGE = Path(monoplane.__file__).parent


def test_every_kernel_of_the_package_is_listed():
    defined = set()
    for path in PACKAGE.rglob("*.py"):
        text = path.read_text()
        module = ".".join(("monoplane", *path.relative_to(PACKAGE).with_suffix("").parts))
        for name in re.findall(r"^@kernel\s*\ndef (\w+)", text, re.M):
            defined.add(f"{module}.{name}")
    assert defined, "no @kernel found: has the decorator been renamed?"
    listed = set(package_kernels())
    assert defined <= listed, sorted(defined - listed)
    assert "monoplane.algorithm.lattice_kernels" in kernel_modules()  # plain numba.njit kernels too


def test_warmup_reaches_every_kernel_in_a_fresh_process():
    # A fresh process: kernels compiled by other tests in this one would hide a miss.
    proc = subprocess.run([sys.executable, "-m", "monoplane.warmup", "--quiet", "--no-report"],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    match = re.search(r"(\d+) of (\d+) kernels compiled or loaded", proc.stdout)
    assert match, proc.stdout
    assert match.group(1) == match.group(2) and int(match.group(2)) >= 30, proc.stdout
    assert "not reached" not in proc.stdout
