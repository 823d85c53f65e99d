"""Names of the simulated rig's scenes, for checking a config before any device is opened.

The scenes themselves live in :mod:`mock_devices.scenes` (simulation is hardware behind the
driver interfaces, so only ``rig/hardware`` reaches into ``mock_devices``).
"""

from __future__ import annotations

from rig.errors import ConfigError


def scene_names() -> tuple[str, ...]:
    """Scene names the simulated camera can look at (``[simulation] scene``, ``rig demo --scene``)."""
    from mock_devices.scenes import SCENES

    return tuple(SCENES)


def check_scene_name(scene: str, where: str) -> None:
    """Raise ConfigError naming ``where`` unless ``scene`` is one of :func:`scene_names`."""
    names = scene_names()
    if scene not in names:
        raise ConfigError(f"{where}: [simulation] scene: expected one of {', '.join(names)}, found {scene!r}")
