"""The README's promises that a test can check: the CI command, the CLI it shows."""

import re
from pathlib import Path

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
