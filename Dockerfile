# pkwbus service image.
#
#   docker build -t pkwbus .        (or: podman build -t pkwbus .)
#
# Plain Dockerfile instructions only: no "# syntax" parser directive (which
# makes BuildKit fetch a frontend image from a registry, and fail offline),
# no RUN --mount, no heredocs. The classic builder, BuildKit and Buildah
# (podman build) all build it as it is. The runtime dependencies are
# installed at the exact versions of constraints.txt, so a rebuild gets the
# same packages.
#
# Demo on simulated drives (no hardware):
#   docker run --rm -p 9725:9725 pkwbus run --config /usr/share/pkwbus/demo.yaml --listen 0.0.0.0:9725
#
# Real lines: mount the configuration at /etc/pkwbus/config.yaml (the default
# command reads it), pass the serial device and keep the audit database on a
# volume (see docs/deploy.md):
#   docker run -d -p 9725:9725 \
#     -v "$PWD/config.yaml:/etc/pkwbus/config.yaml:ro" \
#     -v pkwbus-data:/var/lib/pkwbus \
#     --device /dev/serial/by-id/usb-FTDI_...-if00-port0:/dev/ttyUSB0 \
#     pkwbus
#
# The working directory /var/lib/pkwbus is the only place the service user
# can write: a relative `audit_db: var/audit.sqlite` lands there.

ARG PYTHON_VERSION=3.12

# --- builder: pkwbus and its pinned dependencies in a venv --------------------
FROM python:${PYTHON_VERSION}-slim-bookworm AS builder

ENV PIP_DISABLE_PIP_VERSION_CHECK=1 \
    PIP_NO_CACHE_DIR=1

WORKDIR /src
COPY constraints.txt pyproject.toml README.md LICENSE ./
COPY src ./src
RUN python -m venv /opt/pkwbus \
    && /opt/pkwbus/bin/pip install --no-cache-dir -c constraints.txt ".[mqtt]"

# --- final: the venv, no build tools -------------------------------------------
FROM python:${PYTHON_VERSION}-slim-bookworm

LABEL org.opencontainers.image.title="pkwbus" \
      org.opencontainers.image.description="RS-485 bus master for the PKW parameter channel of Danfoss FC and Siemens USS drives, with Prometheus metrics" \
      org.opencontainers.image.licenses="Apache-2.0"

ENV PATH=/opt/pkwbus/bin:$PATH \
    PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1 \
    PKWBUS_HEALTHCHECK_URL=http://127.0.0.1:9725/healthz

# Fixed numeric ids so that Kubernetes' runAsNonRoot can verify the user and
# volume ownership is predictable. The user is a member of dialout (gid 20),
# the group of serial devices on Debian and Ubuntu hosts.
RUN groupadd --system --gid 10001 pkwbus \
    && useradd --system --uid 10001 --gid pkwbus --groups dialout \
       --home-dir /var/lib/pkwbus --no-create-home --shell /usr/sbin/nologin pkwbus \
    && mkdir -p /etc/pkwbus /var/lib/pkwbus /usr/share/pkwbus \
    && chown pkwbus:pkwbus /var/lib/pkwbus

# The venv only: no build tools, no wheels, no source in the final image. The
# same base image, so the venv's interpreter path is valid here.
COPY --from=builder /opt/pkwbus /opt/pkwbus

COPY config/demo.yaml /usr/share/pkwbus/demo.yaml

# The uid alone, no group: the runtime then takes the primary and the
# supplementary groups of uid 10001 from the image's /etc/group, dialout
# included, so a serial device passed in with --device (group dialout, mode
# 0660) is readable without --group-add. USER 10001:10001 would drop dialout.
USER 10001
WORKDIR /var/lib/pkwbus
EXPOSE 9725

HEALTHCHECK --interval=30s --timeout=5s --start-period=20s --retries=3 \
    CMD ["python", "-c", "import os, sys, urllib.request; sys.exit(0 if urllib.request.urlopen(os.environ['PKWBUS_HEALTHCHECK_URL'], timeout=4).status == 200 else 1)"]

ENTRYPOINT ["pkwbus"]
CMD ["run", "--config", "/etc/pkwbus/config.yaml", "--listen", "0.0.0.0:9725"]
