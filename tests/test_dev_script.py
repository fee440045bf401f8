"""``./dev``, the README's quick start and CI's entry point: its Python 3.12 discovery on fake
machine layouts (real files in temporary folders, the real interpreter symlinked in), the message
when there is none, the skipped reinstall and pytest's exit 5 (no tests) failing the run."""

from __future__ import annotations

import hashlib
import os
import pathlib
import subprocess
import sys
import sysconfig

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
DEV = ROOT / "dev"
REAL = pathlib.Path(os.path.realpath(sys._base_executable))   # the Python 3.12 running these tests
SYSTEM_PLACES = ("/usr/local/bin/python3.12", "/opt/homebrew/bin/python3.12", "/usr/bin/python3.12",
                 "/opt/local/bin/python3.12", "/Library/Frameworks/Python.framework/Versions/3.12/bin/python3.12")


def _script(path: pathlib.Path, body: str) -> pathlib.Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("#!/bin/sh\n" + body + "\n")
    path.chmod(0o755)
    return path


def _link(path: pathlib.Path) -> pathlib.Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.symlink_to(REAL)
    return path


def _pyenv_shim(path: pathlib.Path, name: str) -> pathlib.Path:
    """What pyenv's shim does when 3.12 is installed but not the global version."""
    return _script(path / name, f'echo "pyenv: {name}: command not found" >&2; exit 127')


def _find(tmp_path, **env) -> subprocess.CompletedProcess:
    base = {"PATH": str(tmp_path / "bin"), "HOME": str(tmp_path / "home")}
    (tmp_path / "bin").mkdir(exist_ok=True)
    return subprocess.run(["/bin/sh", str(DEV), "find-python"], env={**base, **env}, capture_output=True,
                          text=True, stdin=subprocess.DEVNULL, timeout=60)


def test_the_real_interpreter_is_python_3_12():
    assert sys.version_info[:2] == (3, 12) and REAL.is_file()


def test_python3_12_on_path(tmp_path):
    exe = _link(tmp_path / "bin" / "python3.12")
    r = _find(tmp_path)
    assert r.returncode == 0 and r.stdout.strip() == str(exe), r.stderr


def test_python3_on_path_when_it_is_3_12(tmp_path):
    _pyenv_shim(tmp_path / "bin", "python3.12")
    exe = _link(tmp_path / "bin" / "python3")
    r = _find(tmp_path)
    assert r.returncode == 0 and r.stdout.strip() == str(exe), r.stderr


def test_pyenv_non_global_version(tmp_path):
    """The issue's machine: ``python3.12`` is a pyenv shim that fails, 3.12 is installed in pyenv."""
    root = tmp_path / "somewhere" / "pyenv-root"
    _pyenv_shim(tmp_path / "bin", "python3.12")
    _pyenv_shim(tmp_path / "bin", "python3")
    _script(tmp_path / "bin" / "pyenv", f'[ "$1" = root ] && echo "{root}"')
    _link(root / "versions" / "3.11.9" / "bin" / "python3.11")
    exe = _link(root / "versions" / "3.12.7" / "bin" / "python3.12")
    r = _find(tmp_path)
    assert r.returncode == 0 and r.stdout.strip() == str(exe), r.stderr


@pytest.mark.parametrize("where", ["PYENV_ROOT", "home"])
def test_pyenv_without_the_pyenv_command(tmp_path, where):
    root = tmp_path / "pyenv" if where == "PYENV_ROOT" else tmp_path / "home" / ".pyenv"
    exe = _link(root / "versions" / "3.12.2" / "bin" / "python3.12")
    r = _find(tmp_path, **({"PYENV_ROOT": str(root)} if where == "PYENV_ROOT" else {}))
    assert r.returncode == 0 and r.stdout.strip() == str(exe), r.stderr


def test_uv_managed_install(tmp_path):
    exe = _link(tmp_path / "home" / ".local" / "share" / "uv" / "python" / "cpython-3.12.5-linux-x86_64-gnu"
                / "bin" / "python3.12")
    r = _find(tmp_path)
    assert r.returncode == 0 and r.stdout.strip() == str(exe), r.stderr


def test_explicit_choice_wins_and_is_checked(tmp_path):
    _link(tmp_path / "bin" / "python3.12")
    chosen = _link(tmp_path / "mine" / "python")
    r = _find(tmp_path, DEFGRASP_PYTHON=str(chosen))
    assert r.returncode == 0 and r.stdout.strip() == str(chosen)
    broken = _script(tmp_path / "mine" / "broken", "exit 1")
    r = _find(tmp_path, DEFGRASP_PYTHON=str(broken))
    assert r.returncode == 1 and f"DEFGRASP_PYTHON={broken} is not a Python 3.12" in r.stderr


def test_no_python_3_12_says_what_to_install(tmp_path):
    if any(os.path.exists(p) for p in SYSTEM_PLACES):
        pytest.skip("this machine has a Python 3.12 in a system place the script always checks")
    shim = _pyenv_shim(tmp_path / "bin", "python3.12")
    old = _script(tmp_path / "bin" / "python3", 'exit 1')             # stands for a Python 3.11
    broken = _script(tmp_path / "home" / ".pyenv" / "versions" / "3.12.0" / "bin" / "python3.12", "exit 1")
    r = _find(tmp_path)
    assert r.returncode == 1 and r.stdout == ""
    assert "Python 3.12 not found" in r.stderr
    assert all(str(p) in r.stderr for p in (shim, old, broken)), r.stderr
    for hint in ("apt-get install python3.12 python3.12-venv", "brew install python@3.12", "pyenv install 3.12",
                 "uv python install 3.12", "DEFGRASP_PYTHON"):
        assert hint in r.stderr


def _repo_with_venv(tmp_path: pathlib.Path, tests: str | None) -> pathlib.Path:
    """A copy of ``dev`` next to a pyproject.toml and a real Python 3.12 venv that sees this
    environment's packages (a .pth file), stamped as installed: ``./dev test`` must not reinstall."""
    repo = tmp_path / "repo"
    repo.mkdir()
    (repo / "dev").write_bytes(DEV.read_bytes())
    (repo / "dev").chmod(0o755)
    (repo / "pyproject.toml").write_text('[project]\nname = "x"\n')
    subprocess.run([str(REAL), "-m", "venv", "--without-pip", str(repo / ".venv")], check=True)
    venv_py = repo / ".venv" / "bin" / "python"
    purelib = subprocess.run([str(venv_py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                             check=True, capture_output=True, text=True).stdout.strip()
    pathlib.Path(purelib, "outer.pth").write_text(sysconfig.get_paths()["purelib"] + "\n")
    digest = hashlib.sha256((repo / "pyproject.toml").read_bytes()).hexdigest()
    (repo / ".venv" / ".defgrasp-installed").write_text(f"{digest} {sys.version.split()[0]}\n")
    if tests is not None:
        (repo / "tests").mkdir()
        (repo / "tests" / "test_one.py").write_text(tests)
    return repo


def _dev_test(repo: pathlib.Path) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in ("CI", "PYTHONPATH")}
    return subprocess.run(["./dev", "test", "-q"], cwd=repo, env=env, capture_output=True, text=True,
                          stdin=subprocess.DEVNULL, timeout=300)


def test_dev_test_skips_the_install_when_up_to_date_and_passes_pytest_through(tmp_path):
    repo = _repo_with_venv(tmp_path, "def test_ok():\n    assert 1 + 1 == 2\n")
    r = _dev_test(repo)
    assert r.returncode == 0 and "1 passed" in r.stdout, r.stdout + r.stderr
    assert "installing" not in r.stderr
    (repo / "tests" / "test_one.py").write_text("def test_bad():\n    assert 1 + 1 == 3\n")
    assert _dev_test(repo).returncode == 1


def test_no_tests_collected_fails_the_run(tmp_path):
    repo = _repo_with_venv(tmp_path, None)
    r = _dev_test(repo)
    assert r.returncode == 5 and "collected no tests" in r.stderr, r.stdout + r.stderr


def test_ci_runs_exactly_the_readme_test_command():
    readme = (ROOT / "README.md").read_text()
    assert "./dev demo" in readme and "./dev test" in readme
    ci = (ROOT / ".ci" / "run").read_text()
    assert [ln for ln in ci.splitlines() if ln.startswith("exec")] == ['exec ./dev test "$@"']
    assert os.access(DEV, os.X_OK)


def test_a_broken_venv_is_reported_not_deleted(tmp_path):
    repo = _repo_with_venv(tmp_path, None)
    (repo / ".venv" / "bin" / "python").unlink()          # e.g. an interrupted venv creation
    r = _dev_test(repo)
    assert r.returncode == 1 and "is not a working Python 3.12 venv" in r.stderr and "rm -rf .venv" in r.stderr
    assert (repo / ".venv" / ".defgrasp-installed").exists()
