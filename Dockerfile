# syntax=docker/dockerfile:1
#
# pkwbus service image.
#
#   docker build -t pkwbus .
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
#     --group-add dialout pkwbus
#
# The working directory /var/lib/pkwbus is the only place the service user
# can write: a relative `audit_db: var/audit.sqlite` lands there.

ARG PYTHON_VERSION=3.12

# --- builder: wheels of pkwbus and of its dependencies -----------------------
FROM python:${PYTHON_VERSION}-slim-bookworm AS builder

ENV PIP_DISABLE_PIP_VERSION_CHECK=1 \
    PIP_NO_CACHE_DIR=1

WORKDIR /src
COPY pyproject.toml README.md LICENSE ./
COPY src ./src
RUN pip wheel --no-cache-dir --wheel-dir /wheels .

# --- final: the wheels installed, no build tools ------------------------------
FROM python:${PYTHON_VERSION}-slim-bookworm

LABEL org.opencontainers.image.title="pkwbus" \
      org.opencontainers.image.description="RS-485 bus master for the PKW parameter channel of Danfoss FC and Siemens USS drives, with Prometheus metrics" \
      org.opencontainers.image.licenses="Apache-2.0"

ENV PYTHONDONTWRITEBYTECODE=1 \
    PYTHONUNBUFFERED=1 \
    PIP_DISABLE_PIP_VERSION_CHECK=1 \
    PKWBUS_HEALTHCHECK_URL=http://127.0.0.1:9725/healthz

# Fixed numeric ids so that Kubernetes' runAsNonRoot can verify the user and
# volume ownership is predictable. dialout (gid 20 on Debian) grants access
# to serial devices passed in with --device.
RUN groupadd --system --gid 10001 pkwbus \
    && useradd --system --uid 10001 --gid pkwbus --groups dialout \
       --home-dir /var/lib/pkwbus --no-create-home --shell /usr/sbin/nologin pkwbus \
    && mkdir -p /etc/pkwbus /var/lib/pkwbus /usr/share/pkwbus \
    && chown pkwbus:pkwbus /var/lib/pkwbus

# The wheels come in through a bind mount, so they never become a layer.
RUN --mount=type=bind,from=builder,source=/wheels,target=/wheels \
    pip install --no-cache-dir --no-index --find-links=/wheels /wheels/pkwbus-*.whl

COPY config/demo.yaml /usr/share/pkwbus/demo.yaml

USER 10001:10001
WORKDIR /var/lib/pkwbus
EXPOSE 9725

HEALTHCHECK --interval=30s --timeout=5s --start-period=20s --retries=3 \
    CMD ["python", "-c", "import os, sys, urllib.request; sys.exit(0 if urllib.request.urlopen(os.environ['PKWBUS_HEALTHCHECK_URL'], timeout=4).status == 200 else 1)"]

ENTRYPOINT ["pkwbus"]
CMD ["run", "--config", "/etc/pkwbus/config.yaml", "--listen", "0.0.0.0:9725"]
