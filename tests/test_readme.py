"""The README's promises that a test can check: the CI command, the CLI it shows."""

import re
import shutil
import site
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


def _bash_blocks() -> list[str]:
    text = (ROOT / "README.md").read_text()
    return re.findall(r"```bash\n(.*?)```", text, flags=re.S)


def test_ci_runs_the_readme_test_command():
    ci = (ROOT / ".ci" / "run").read_text()
    command = re.search(r"TEST_COMMAND='(.*)'", ci).group(1)
    assert any(block.strip() == command for block in _bash_blocks()), command


def test_readme_gives_two_setup_commands_and_the_main_job():
    blocks = [b.strip() for b in _bash_blocks()]
    assert len(blocks) == 2
    main_job, tests = blocks
    assert "pip install" in main_job and "biso-cosim run --route loop600" in main_job
    assert "pip install" in tests and tests.endswith("pytest")
    # no draft markers left where measured numbers belong
    text = (ROOT / "README.md").read_text()
    leftover = re.findall(r"PLACEHOLDER|\b(?:REPRO|BENCH)_[A-Z]+\b|^RESULTS$|\bTODO\b", text, flags=re.M)
    assert not leftover, leftover


def _api_snippet() -> str:
    text = (ROOT / "README.md").read_text()
    section = text[text.index("## Python API"):]
    return re.search(r"```python\n(.*?)```", section, flags=re.S).group(1)


@pytest.mark.slow
def test_a_non_editable_install_imports_from_the_repository_root_and_runs_the_api_snippet(tmp_path):
    """``pip install .`` (not editable) into a fresh venv: from the repository root (where the
    source tree comes first on sys.path) and from elsewhere (the installed copy), biso_cosim
    and its sub-packages envs and fmu import, and the README's API snippet runs. The
    dependencies come from this test's environment (a .pth file); pip fetches only the build
    requirements (setuptools, wheel) for its isolated build, as ``pip install .`` does."""
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    python = venv / "bin" / "python"
    target = Path(subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                                 check=True, capture_output=True, text=True).stdout.strip())
    ours = [p for p in site.getsitepackages() if Path(p).is_dir()]
    (target / "_test_dependencies.pth").write_text("\n".join(ours) + "\n")
    build = tmp_path / "src"  # a copy without build products, as a fresh clone has
    shutil.copytree(ROOT, build, ignore=shutil.ignore_patterns(".venv", ".git", "*.egg-info", "build", "__pycache__",
                                                               "out", ".pytest_cache"))
    done = subprocess.run([sys.executable, "-m", "pip", "--python", str(python), "install", "-q", "--no-deps",
                           str(build)], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    installed = target / "biso_cosim"
    assert (installed / "envs" / "__init__.py").is_file() and (installed / "fmu" / "native" / "include").is_dir()
    check = "import biso_cosim, biso_cosim.envs, biso_cosim.fmu; print(biso_cosim.envs.__file__)"
    # from the root the source tree comes first, with envs/ beside the package (biso_cosim._source_tree)
    for cwd, where in ((ROOT, ROOT / "envs"), (tmp_path, installed / "envs")):
        done = subprocess.run([str(python), "-c", check], cwd=cwd, capture_output=True, text=True)
        assert done.returncode == 0, done.stderr
        assert Path(done.stdout.strip()) == where / "__init__.py"
    snippet = _api_snippet().replace('run_route("figure8", seed=0', 'run_route("figure8", seed=0, duration_s=3.0')
    done = subprocess.run([str(python), "-c", snippet + "\nassert q_wb.shape == (imu.gyro_b.shape[0], 4)\n"],
                          cwd=ROOT, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr


def test_the_source_tree_finder_acts_only_in_a_source_tree(tmp_path):
    from biso_cosim import _source_tree

    assert _source_tree.install(ROOT / "biso_cosim")  # this repository: envs/ and fmu/ beside the package
    installed = tmp_path / "site" / "biso_cosim"
    (installed / "envs").mkdir(parents=True)
    (installed / "envs" / "__init__.py").write_text("")
    (tmp_path / "site" / "pyproject.toml").write_text("")
    assert not _source_tree.install(installed)  # an installed copy has them inside
    assert not _source_tree.install(tmp_path / "elsewhere" / "biso_cosim")
