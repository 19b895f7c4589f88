"""The base image made from the Debian archive, and podman build of the Dockerfile as it is."""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import sys
import tempfile
from pathlib import Path

from .processes import podman, run
from .report import CheckFailed, say
from .settings import (
    BASE_PACKAGES,
    BASE_RECIPE,
    BASE_TAG,
    CACHE_DIR,
    IMAGE,
    PYTHON_VERSION,
    SUITE,
)

# --- the base image -------------------------------------------------------------------


def debian_mirror() -> str:
    sources = Path("/etc/apt/sources.list.d/debian.sources")
    if sources.is_file():
        for line in sources.read_text().splitlines():
            if line.startswith("URIs:") and "security" not in line:
                return line.split()[1]
    listfile = Path("/etc/apt/sources.list")
    if listfile.is_file():
        for line in listfile.read_text().splitlines():
            parts = line.split()
            if parts[:1] == ["deb"] and "security" not in line:
                return next(p for p in parts[1:] if "://" in p)
    return "http://deb.debian.org/debian"


def base_key() -> str:
    text = json.dumps([BASE_RECIPE, SUITE, BASE_PACKAGES, PYTHON_VERSION])
    return hashlib.sha256(text.encode()).hexdigest()[:12]


def make_base() -> str:
    """The base image the Dockerfile starts from, made from the Debian archive.

    Debian's python3 on debootstrap's minbase, with /usr/local/bin/python as the
    python images have it. The root file system is cached as a tarball in
    CACHE_DIR, so a later run on this machine only imports it.
    """
    key = base_key()
    label = f"pkwbus.base-key={key}"
    have = podman(
        "image", "inspect", "--format", '{{index .Labels "pkwbus.base-key"}}', BASE_TAG, check=False
    )
    if have.returncode == 0 and have.stdout.strip() == key:
        return "present"
    tarball = CACHE_DIR / f"base-{SUITE}-python{PYTHON_VERSION}-{key}.tar"
    how = "from the cache"
    if not tarball.is_file():
        how = "from the Debian archive"
        CACHE_DIR.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(dir=CACHE_DIR) as tmp:
            root = Path(tmp) / "rootfs"
            mirror = debian_mirror()
            say(f"    debootstrap --variant=minbase {SUITE} from {mirror}")
            run(
                [
                    "debootstrap",
                    "--variant=minbase",
                    f"--include={','.join(BASE_PACKAGES)}",
                    SUITE,
                    str(root),
                    mirror,
                ],
                timeout=900,
            )
            for junk in (
                "var/cache/apt",
                "var/lib/apt/lists",
                "usr/share/doc",
                "usr/share/man",
                "usr/share/info",
                "usr/share/locale",
                "var/log",
            ):
                shutil.rmtree(root / junk, ignore_errors=True)
                (root / junk).mkdir(parents=True, exist_ok=True)
            (root / "var/lib/apt/lists/partial").mkdir(parents=True, exist_ok=True)
            (root / "var/cache/apt/archives/partial").mkdir(parents=True, exist_ok=True)
            (root / "usr/local/bin").mkdir(parents=True, exist_ok=True)
            for name in ("python", "python3"):
                link = root / "usr/local/bin" / name
                link.unlink(missing_ok=True)
                link.symlink_to("/usr/bin/python3")
            # No host name or resolver of the build machine in the image.
            (root / "etc/hostname").write_text("localhost\n")
            (root / "etc/resolv.conf").unlink(missing_ok=True)
            partial = tarball.with_suffix(".partial")
            run(["tar", "--numeric-owner", "-C", str(root), "-cf", str(partial), "."], timeout=300)
            partial.rename(tarball)
    podman(
        "import",
        "--change",
        f"LABEL {label}",
        "--change",
        "ENV LANG=C.UTF-8",
        "--change",
        "ENV PATH=/usr/local/sbin:/usr/local/bin:/usr/sbin:/usr/bin:/sbin:/bin",
        "--change",
        'CMD ["python3"]',
        str(tarball),
        BASE_TAG,
    )
    return how


# --- building -------------------------------------------------------------------------


def pip_mounts(state: Path) -> list[str]:
    """-v options giving pip inside the build this machine's index and CA bundle, read-only.

    Nothing of it lands in a layer: podman build's -v mounts only exist while a
    RUN instruction runs.
    """
    out = run([sys.executable, "-m", "pip", "config", "list"], check=False).stdout
    conf: dict[str, str] = {}
    for line in out.splitlines():
        key, _, value = line.partition("=")
        conf[key.split(".", 1)[-1]] = value.strip().strip("'\"")
    for env, key in (
        ("PIP_INDEX_URL", "index-url"),
        ("PIP_EXTRA_INDEX_URL", "extra-index-url"),
        ("PIP_TRUSTED_HOST", "trusted-host"),
        ("PIP_CERT", "cert"),
        ("PIP_PROXY", "proxy"),
        ("PIP_DEFAULT_TIMEOUT", "timeout"),
    ):
        if os.environ.get(env):
            conf[key] = os.environ[env]
    lines = ["[global]"]
    for key in ("index-url", "extra-index-url", "trusted-host", "proxy", "timeout"):
        if key in conf:
            # Local directories of this machine are not in the build container.
            value = " ".join(u for u in conf[key].split() if not u.startswith("file:"))
            if value:
                lines.append(f"{key} = {value}")
    mounts: list[str] = []
    bundle = conf.get("cert") or os.environ.get("SSL_CERT_FILE") or ""
    if not bundle and Path("/etc/ssl/certs/ca-certificates.crt").is_file():
        bundle = "/etc/ssl/certs/ca-certificates.crt"
    if bundle and Path(bundle).is_file():
        mounts += ["-v", f"{Path(bundle).resolve()}:/etc/ssl/certs/ca-certificates.crt:ro"]
        lines.append("cert = /etc/ssl/certs/ca-certificates.crt")
    pipconf = state / "pip.conf"
    pipconf.write_text("\n".join(lines) + "\n")
    mounts += ["-v", f"{pipconf}:/etc/pip.conf:ro"]
    return mounts


def image_id(ref: str) -> str:
    out = podman("image", "inspect", "--format", "{{.Id}}", ref, check=False)
    return out.stdout.strip() if out.returncode == 0 else ""


def drop_replaced(ref: str, before: str) -> None:
    """Remove the image a rebuild untagged, so runs do not pile up old images."""
    if before and image_id(ref) != before:
        podman("rmi", before, check=False)


def build(state: Path) -> None:
    before = image_id(IMAGE)
    args = [
        "build",
        "--format",
        "docker",
        "--build-arg",
        f"PYTHON_VERSION={PYTHON_VERSION}",
        "--pull=never",
        *pip_mounts(state),
        "-t",
        IMAGE,
        "-f",
        "Dockerfile",
        ".",
    ]
    proc = podman(*args, check=False, timeout=900)
    if proc.returncode != 0:
        raise CheckFailed("podman build failed:\n" + (proc.stdout + proc.stderr)[-4000:])
    drop_replaced(IMAGE, before)
