"""Sensor size of Prophesee recordings whose header does not state it.

Old RAW headers (Metavision < 2.2) have no ``% format`` width/height and no ``% geometry``; OpenEB
then infers the size from the camera. These tables are OpenEB's: the HAL plugins' sensor sizes
(``hal_psee_plugins`` raw constants: gen3/gen31 VGA 640x480, gen4/gen41 HD 1280x720) and the
system-ID map of ``PseeRawFileHeader::check_header``. Later plugins name their sensor (IMX636,
IMX646: HD 1280x720; GenX320: 320x320). Anything else gives None: the size is then unknown and
reported as such, never guessed.
"""

from __future__ import annotations

import re
from collections.abc import Mapping

VGA = (640, 480)
HD = (1280, 720)
GENX320 = (320, 320)

SYSTEM_ID_GEOMETRY: dict[int, tuple[int, int]] = {
    0x15: VGA,  # CCAM3 Gen3
    0x1C: VGA,  # CCAM3 Gen3.1
    0x1A: HD,  # CCAM3 Gen4
    0x17: VGA,  # CCAM4 Gen3
    0x97: VGA,  # CCAM4 Gen3 EVK
    0x19: VGA,  # CCAM4 Gen3 rev B
    0x99: VGA,  # CCAM4 Gen3 rev B EVK
    0x1D: VGA,  # CCAM4 Gen3 rev B EVK bridge
    0x23: VGA,  # CCAM5 Gen3.1 (EVK3 Gen3.1 EVT2)
    0x1E: HD,  # CCAM5 Gen4
    0x2E: HD,  # CCAM5 Gen4 fixed frame
    0x21: VGA,  # VisionCam Gen3
    0xA1: VGA,  # VisionCam Gen3 EVK
    0x22: VGA,  # VisionCam Gen3.1
    0xA2: VGA,  # VisionCam Gen3.1 EVK
    0x29: VGA,  # EVK2 Gen3.1
    0x1F: HD,  # EVK2 Gen4
    0x27: HD,  # EVK2 Gen4.1
    0x28: VGA,  # EVK3 Gen3.1 EVT3
    0x30: HD,  # EVK3 Gen4.1
    0x32: HD,  # EVK2 IMX636
    0x31: HD,  # EVK3 IMX636
}
"""OpenEB's ``system_ID`` -> (width, height) for recordings of Prophesee's own cameras."""

# Sensor tokens in plugin names (hal_plugin_gen3_fx3, hal_plugin_gen41_evk3, hal_plugin_imx636_evk4,
# evc3a_plugin_gen31, ...), most specific first.
_PLUGIN_SENSORS: tuple[tuple[str, tuple[int, int]], ...] = (
    (r"genx320", GENX320),
    (r"gen3(1)?(?![0-9])", VGA),
    (r"gen4(1)?(?![0-9])", HD),
    (r"imx636|imx646", HD),
    (r"evk4", HD),  # the EVK4 HD carries an IMX636
)

_SENSOR_GENERATIONS = {"3.0": VGA, "3.1": VGA, "4.0": HD, "4.1": HD, "4.2": HD}


def geometry_from_plugin(name: str) -> tuple[int, int] | None:
    """Sensor (width, height) from a HAL plugin or camera name, or None if it does not say."""
    lowered = name.lower()
    for pattern, size in _PLUGIN_SENSORS:
        if re.search(pattern, lowered):
            return size
    return None


def geometry_from_system_id(value: str) -> tuple[int, int] | None:
    """Sensor (width, height) from a Prophesee ``system_ID`` header value, or None."""
    try:
        system_id = int(value, 0)
    except ValueError:
        return None
    return SYSTEM_ID_GEOMETRY.get(system_id)


def inferred_geometry(header: Mapping[str, str]) -> tuple[int, int] | None:
    """Sensor size from the camera fields of a header without geometry, or None.

    Tries the plugin name, the camera/sensor names, the sensor generation, then the system ID
    (only for Prophesee's own cameras, as OpenEB does).
    """
    for key in ("plugin_name", "camera_name", "sensor_name"):
        if header.get(key):
            size = geometry_from_plugin(header[key])
            if size:
                return size
    generation = header.get("sensor_generation") or header.get("generation")
    if generation in _SENSOR_GENERATIONS:
        return _SENSOR_GENERATIONS[generation]
    integrator = header.get("camera_integrator_name") or header.get("integrator_name") or "Prophesee"
    if integrator == "Prophesee" and header.get("system_ID"):
        return geometry_from_system_id(header["system_ID"])
    return None
