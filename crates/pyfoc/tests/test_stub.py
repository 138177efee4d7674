"""The stub python/pyfoc/__init__.pyi matches the built module: mypy's stubtest compares every name, signature,
property and enum member of the stub with the runtime (allowlist: crates/pyfoc/stubtest-allowlist.txt)."""
import pathlib
import subprocess
import sys

HERE = pathlib.Path(__file__).resolve().parent


def test_stub_matches_the_module():
    allowlist = HERE.parent / "stubtest-allowlist.txt"
    done = subprocess.run(
        [sys.executable, "-m", "mypy.stubtest", "pyfoc", "--allowlist", str(allowlist)],
        capture_output=True,
        text=True,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert "Success" in done.stdout
