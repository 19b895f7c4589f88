"""constraints.txt pins exactly the runtime closure of pyproject.toml's dependencies."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from packaging.requirements import Requirement
from packaging.utils import canonicalize_name

from tests.deploy.constraints import (
    CONSTRAINTS,
    LockError,
    closure_problems,
    disagreements,
    read_lock,
    runtime_closure,
    runtime_requirements,
)


def test_every_runtime_dependency_is_pinned_within_its_specifier() -> None:
    problems = disagreements(runtime_requirements(), read_lock())
    assert not problems, f"pyproject.toml and {CONSTRAINTS.name} disagree:\n" + "\n".join(problems)


def test_the_lock_is_the_whole_runtime_closure_as_installed() -> None:
    """Nothing missing, nothing extra (no test tools), each pin what its requirers allow.

    The dependencies of each package come from its installed metadata, so
    this also says the environment is the locked one: make installs with
    ``pip install -c constraints.txt``.
    """
    problems = closure_problems(runtime_closure(), read_lock())
    assert not problems, f"{CONSTRAINTS.name} is not the runtime closure:\n" + "\n".join(problems)


def test_a_disagreement_is_found() -> None:
    pins = {canonicalize_name("fastapi"): "0.110.0", canonicalize_name("PyYAML"): "6.0.3"}
    reqs = [Requirement(r) for r in ("fastapi>=0.115", "pyyaml>=6.0", "uvicorn>=0.29")]
    assert disagreements(reqs, pins) == [
        "fastapi>=0.115: pinned at 0.110.0, outside >=0.115",
        "uvicorn>=0.29: not pinned",
    ]


def test_a_pin_of_a_package_outside_the_closure_or_too_old_for_its_requirer() -> None:
    closure = {
        canonicalize_name("starlette"): ("1.0.0", [("fastapi", Requirement("starlette>=1.6"))]),
    }
    pins = {canonicalize_name("starlette"): "1.0.0", canonicalize_name("pytest"): "8.0.0"}
    assert closure_problems(closure, pins) == [
        "pytest==8.0.0: not a runtime dependency",
        "starlette==1.0.0: fastapi needs starlette>=1.6",
    ]


@pytest.mark.parametrize("line", ["fastapi>=0.110", "fastapi", "fastapi==0.1 ; x", "-e ."])
def test_only_exact_pins_are_accepted(tmp_path: Path, line: str) -> None:
    path = tmp_path / "constraints.txt"
    path.write_text(f"# comment\nuvicorn==0.54.0\n{line}\n")
    with pytest.raises(LockError, match=":3: "):
        read_lock(path)


def test_the_image_and_make_install_with_the_constraints() -> None:
    root = CONSTRAINTS.parent
    dockerfile = (root / "Dockerfile").read_text()
    # The image installs the extras that are pinned with the runtime (the mqtt output).
    assert re.search(r'pip install [^\n]*-c constraints\.txt "\.\[mqtt\]"', dockerfile)
    makefile = (root / "Makefile").read_text()
    assert re.search(r"pip install [^\n]*-c constraints\.txt -e '\.\[test\]'", makefile)
