"""The access-control rules of a rig, made from the service table: each service's identity may publish,
subscribe to and declare exactly the keys its entry names (:mod:`.table`), for the rig's camera and
point sensor; :mod:`flagtrack.daemon.security.acl` turns those rights into Zenoh's rules."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from flagtrack.daemon.rig.table import SERVICE_NAMES, SERVICES, ServiceSpec, service_spec
from flagtrack.daemon.schema import Keys
from flagtrack.daemon.security import acl
from flagtrack.daemon.security.acl import Rights
from flagtrack.daemon.security.config import SecurityConfig


def expand_keys(
    keys: Keys, names: Sequence[str], camera_ids: Sequence[str], sensor_ids: Sequence[str]
) -> tuple[str, ...]:
    """The key expressions of table key names (``name()``, ``name(camera)``, ``name(sensor)``), in order,
    one per camera or sensor where the name takes one."""
    made: list[str] = []
    for entry in names:
        method, _, argument = entry.partition("(")
        key = getattr(keys, method)
        if argument == ")":
            made.append(key())
        elif argument in ("camera)", "sensor)"):
            made.extend(key(i) for i in (camera_ids if argument == "camera)" else sensor_ids))
        else:
            raise ValueError(f"bad key {entry!r}: name(), name(camera) or name(sensor)")
    return tuple(made)


def spec_rights(keys: Keys, spec: ServiceSpec, camera_ids: Sequence[str], sensor_ids: Sequence[str]) -> Rights:
    """The rights of the service of ``spec`` for these cameras and sensors."""
    if "{camera}" in spec.alive or "{sensor}" in spec.alive:
        ids = camera_ids if "{camera}" in spec.alive else sensor_ids
        tokens = tuple(keys.alive(spec.alive.format(camera=i, sensor=i)) for i in ids)
    else:
        tokens = (keys.alive(spec.alive),) if spec.alive else ()
    return Rights(
        publish=expand_keys(keys, spec.publishes, camera_ids, sensor_ids),
        subscribe=expand_keys(keys, spec.subscribes, camera_ids, sensor_ids),
        tokens=tokens,
        watch=spec.watches,
    )


def role_rights(keys: Keys, role: str, camera_ids: Sequence[str], sensor_ids: Sequence[str]) -> Rights:
    """The rights of service ``role`` (a name of the table) for these cameras and sensors.

    Raises:
        ValueError: no such service.
    """
    try:
        spec = service_spec(role)
    except KeyError:
        raise ValueError(f"unknown service {role!r} (known: {', '.join(SERVICE_NAMES)})") from None
    return spec_rights(keys, spec, camera_ids, sensor_ids)


def service_rights(keys: Keys, camera_ids: Sequence[str], sensor_ids: Sequence[str]) -> dict[str, Rights]:
    """Every service's rights, by name, in table order."""
    return {spec.name: spec_rights(keys, spec, camera_ids, sensor_ids) for spec in SERVICES}


def identity_rights(
    keys: Keys, security: SecurityConfig, camera_ids: Sequence[str], sensor_ids: Sequence[str]
) -> dict[str, Rights]:
    """Every identity the rules know and its rights (see :func:`~flagtrack.daemon.security.acl.identity_rights`)."""
    return acl.identity_rights(keys, security, service_rights(keys, camera_ids, sensor_ids))


def access_control(
    keys: Keys, security: SecurityConfig, camera_ids: Sequence[str], sensor_ids: Sequence[str] = ()
) -> dict[str, Any]:
    """The Zenoh ``access_control`` section of a rig with these cameras and sensors."""
    return acl.access_control(keys, security, service_rights(keys, camera_ids, sensor_ids))
