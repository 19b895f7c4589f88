"""The Dockerfile: a numeric USER that keeps dialout, no BuildKit-only syntax, a full context.

Building the image needs a container engine; these read the file.
"""

from __future__ import annotations

import re
import shlex
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
DOCKERFILE = ROOT / "Dockerfile"
DOCKERIGNORE = ROOT / ".dockerignore"


def instructions(text: str) -> list[tuple[str, str]]:
    """(INSTRUCTION, arguments) with continuation lines joined and comments dropped."""
    out: list[tuple[str, str]] = []
    current = ""
    for line in text.splitlines():
        stripped = line.strip()
        if stripped.startswith("#") or (not stripped and not current):
            continue
        if stripped.endswith("\\"):
            current += stripped[:-1] + " "
            continue
        current += stripped
        word, _, rest = current.partition(" ")
        out.append((word.upper(), rest.strip()))
        current = ""
    return out


def flags_of(args: str) -> list[str]:
    """The names of the leading ``--flag[=value]`` options of an instruction."""
    names = []
    for token in args.split():
        if not token.startswith("--"):
            break
        names.append(token[2:].split("=", 1)[0])
    return names


TEXT = DOCKERFILE.read_text()
STEPS = instructions(TEXT)


def test_no_syntax_directive() -> None:
    """A ``# syntax=`` line makes BuildKit fetch a frontend image: offline builds fail."""
    directives = [x for x in TEXT.splitlines() if re.match(r"#\s*syntax\s*=", x, re.I)]
    assert not directives


def test_no_buildkit_only_instructions() -> None:
    """What the classic builder rejects: RUN --mount/--network/--security, COPY --link or
    --chmod, heredocs."""
    problems = []
    for word, args in STEPS:
        flags = set(flags_of(args))
        if word == "RUN" and {"mount", "network", "security"} & flags:
            problems.append(f"{word} {args[:60]}")
        if word in ("COPY", "ADD") and {"link", "chmod", "parents", "exclude"} & flags:
            problems.append(f"{word} {args[:60]}")
        if re.search(r"<<-?\s*['\"]?[A-Za-z_]+", args):
            problems.append(f"{word}: heredoc")
    assert not problems


def test_user_is_a_numeric_uid_that_keeps_dialout() -> None:
    """``USER uid`` alone: the runtime takes the groups from /etc/group (dialout
    included); ``USER uid:gid`` would give the container that one group only."""
    users = [args for word, args in STEPS if word == "USER"]
    assert users, "no USER: the service would run as root"
    assert all(re.fullmatch(r"\d+", u) for u in users), users
    useradd = next(args for word, args in STEPS if word == "RUN" and "useradd" in args)
    words = shlex.split(useradd.split("useradd", 1)[1].split("&&", 1)[0])
    uid = words[words.index("--uid") + 1]
    groups = words[words.index("--groups") + 1].split(",")
    assert users[-1] == uid
    assert "dialout" in groups


def test_copied_files_are_in_the_build_context() -> None:
    """Each COPY from the context is let through by .dockerignore (an allow list)."""
    allowed = [
        x[1:].strip().rstrip("/")
        for x in DOCKERIGNORE.read_text().splitlines()
        if x.startswith("!")
    ]
    missing = []
    for word, args in STEPS:
        if word not in ("COPY", "ADD") or "--from=" in args:
            continue
        *sources, _ = args.split()[len(flags_of(args)) :]
        for source in sources:
            path = source.removeprefix("./").rstrip("/") or "."
            if not any(path == a or path.startswith(a + "/") for a in allowed):
                missing.append(source)
    assert not missing, f"not in the build context (.dockerignore): {missing}"


def test_instructions_parse() -> None:
    words = [w for w, _ in STEPS]
    assert words.count("FROM") == 2
    assert words[-2:] == ["ENTRYPOINT", "CMD"]
