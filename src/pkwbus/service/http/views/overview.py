"""What the overview's row of a drive shows beside its values: how many of its settings
differ from their baseline (``GET /api/v1/drives?view=overview``), as the read model has
it from the settings' sweep (:attr:`pkwbus.master.snapshot.Snapshot.settings`)."""

from __future__ import annotations

from pkwbus.service.runtime import Runtime

__all__ = ["settings_changed"]


def settings_changed(runtime: Runtime, name: str) -> int | None:
    """How many of the drive's swept settings differ from their baseline: those its
    settings view (``GET .../settings``) marks ``changed`` (None: its settings are not
    swept, or not read yet)."""
    settings = runtime.settings
    if settings is None or name not in settings.swept:
        return None
    shown = runtime.snapshot.settings.get(name)
    return shown.changed if shown is not None else None
