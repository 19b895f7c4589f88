"""deploy/image-check's checks, one module a concern; deploy/image_check.py runs them in order.

- settings: what the image must stay within, the names and files the checks use
- report: the timed steps, their ok or FAIL, and the closing verdict
- processes: subprocesses, podman, HTTP, waiting, cleaning up, podman's configuration
- build: the base image from the Debian archive, and podman build of the Dockerfile
- containers: starting the containers and the simulated serial line, waiting for them
- service: the image and the running service (process, health, metrics, API, audit, SIGTERM)
- manifests: the dashboard JSON, the compose file and the Kubernetes manifests, no container
- prometheus: Prometheus scraping the container: the dashboard's queries, the alert
- stack: the compose stack (pkwbus and Prometheus) and podman kube play of gateway-1
"""
