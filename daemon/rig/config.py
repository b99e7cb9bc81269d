"""The rig config: one YAML file describing the bus, the camera, the tracker, the recorder, the viewer,
the tunnel, the supervisor and the point sensor, read once and checked before anything opens.

Example (see ``deploy/rig-*.yaml``)::

    rig: lab1                     # namespace flagtrack/lab1 unless bus.namespace says otherwise
    bus: {listen: ["tcp/127.0.0.1:7447"]}
    camera: {id: cam0, adapter: simulated, simulated: {speed_mps: 6}}
    tracker: {root: [150, 240], length: 300, tau_s: 0.0003}
    recorder: {directory: recordings}
    viewer: {sink: rrd, rrd_path: live.rrd}
    services: [camera, tracker, recorder, viewer]

The sections are :class:`~.sections.RigSections`; the services, the sections each needs and the
files each checks are the service table's (:mod:`.table`).
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from flagtrack.daemon.errors import ConfigError
from flagtrack.daemon.rig.findings import Findings
from flagtrack.daemon.rig.sections import HARDWARE_ADAPTERS, CameraConfig, RigSections, viewer_writes_file
from flagtrack.daemon.rig.table import SERVICE_NAMES, in_table_order
from flagtrack.daemon.schema import Keys
from flagtrack.daemon.security.names import identifier_problem
from flagtrack.daemon.tracking.setup import resolve_calibration
from flagtrack.daemon.transport import BusConfig
from flagtrack.daemon.typed_yaml import from_mapping, load_yaml

__all__ = [
    "HARDWARE_ADAPTERS",
    "SERVICE_NAMES",
    "CameraConfig",
    "RigConfig",
    "check_rig",
    "load_rig",
    "viewer_writes_file",
]


@dataclass(frozen=True)
class RigConfig(RigSections):
    """A rig: its sections (:class:`~.sections.RigSections`), with ``services`` naming services of the
    table, each with the sections it needs, and the bus's access-control rules made from the table."""

    def __post_init__(self) -> None:
        unknown = [name for name in self.services if name not in SERVICE_NAMES]
        if unknown:
            raise ValueError(f"unknown service {unknown[0]!r} in services (known: {', '.join(SERVICE_NAMES)})")
        super().__post_init__()
        for spec in in_table_order(self.services):
            for section in spec.needs:
                if getattr(self, section) is None:
                    raise ValueError(
                        f"the {spec.name} service needs a '{section}:' section (driver: simulated for no hardware)"
                    )
        security = self.bus.security if self.bus is not None else None
        for name, roles in (security.identities if security is not None else {}).items():
            unknown = [role for role in roles if role not in SERVICE_NAMES]
            if unknown:
                raise ConfigError(
                    f"unknown service {unknown[0]!r} (known: {', '.join(SERVICE_NAMES)})",
                    key=f"bus.security.identities.{name}",
                )

    @property
    def bus_config(self) -> BusConfig:
        """The bus section, with the namespace ``flagtrack/<rig>`` unless it is given, and the rig's
        access-control rules when ``bus.security.acl`` is on (:meth:`bus_config_for` also names the
        identity of a process that runs one service)."""
        if self.bus is None:
            return BusConfig(namespace=f"flagtrack/{self.rig}")
        security = self.bus.security
        if security is None or not security.acl:
            return self.bus
        from flagtrack.daemon.rig.access import access_control

        sensors = (self.sensor.id,) if self.sensor is not None else ()
        rules = access_control(Keys(self.bus.namespace), security, (self.camera.id,), sensors)
        return dataclasses.replace(self.bus, access_control=rules)

    def bus_config_for(self, services: Sequence[str], identity: str | None = None) -> BusConfig:
        """:attr:`bus_config` for a process running ``services``: on a secured bus it presents
        ``identity``, else ``bus.security.identity``, else the one service it runs (``flagtrack
        camera`` presents ``camera``); ``flagtrack router`` presents ``router``."""
        cfg = self.bus_config
        security = cfg.security
        if security is None or security.tls is None:
            return cfg
        chosen = identity or security.identity or (services[0] if len(services) == 1 else None)
        if chosen is None or chosen == security.identity:
            return cfg
        return dataclasses.replace(cfg, security=dataclasses.replace(security, identity=chosen))


def load_rig(path: str | Path, services: Sequence[str] | None = None) -> RigConfig:
    """Read and check a rig config; every error names the key and the file.

    Args:
        path: the YAML file.
        services: the services whose files, folders and camera settings are checked (:func:`check_rig`);
            default: the rig's own ``services:``; ``()`` for a caller that checks after changing the rig.

    Raises:
        ConfigError: unreadable file, unknown key, bad value, a missing input file, an output folder
            that cannot be made, a camera setting no camera of the adapter takes.
    """
    data = load_yaml(path)
    if "path" in data:
        raise ConfigError("reserved key", key="path", path=str(path))
    bus = data.get("bus") or {}
    if isinstance(bus, dict) and "access_control" in bus:
        raise ConfigError("made from the rig by bus.security.acl: true, not written", key="bus.access_control")
    security = bus.get("security") if isinstance(bus, dict) else None
    password = security.get("password") if isinstance(security, dict) else None
    if password is not None and not isinstance(password, str):  # (the type error would print it)
        raise ConfigError("must be text: quote it", key="bus.security.password", path=str(path))
    if isinstance(bus, dict) and "namespace" not in bus:
        rig_name = data.get("rig", "default")
        problem = identifier_problem(rig_name, "the name")
        if problem is not None:  # it makes the namespace: name the key the user wrote
            raise ConfigError(problem, key="rig", path=str(path))
        data = {**data, "bus": {**bus, "namespace": f"flagtrack/{rig_name}"}}
    rig = from_mapping(RigConfig, {**data, "path": str(path)}, path=str(path))
    rig = dataclasses.replace(rig, tracker=resolve_calibration(rig.tracker, Path(path).parent))
    check_rig(rig, rig.services if services is None else services)
    return rig


def check_rig(rig: RigConfig, services: Sequence[str], findings: Findings | None = None) -> Findings:
    """Check what ``services`` need of ``rig`` that a file or a setting can say, opening and creating
    nothing: each service's own check of the service table (:mod:`.table`), then the certificates
    the processes of a secured bus present (:mod:`.certificates`).

    Input files must exist (``camera.replay.path``, ``tracker.calibration``); output folders must
    exist or be creatable (``recorder.directory`` and ``path``, the ``.rrd`` file's, ``supervisor.runs_dir``);
    a hardware camera's settings are checked as far as they can be without the device (bias names,
    ROI form); what only the device can tell (an ROI that fits its sensor) is checked when ``up``
    opens it, before anything else (:func:`flagtrack.daemon.rig.build.open_hardware_camera`).

    ``findings``: where what this host lacks goes (default: strict, each raised as an error: what the
    commands that run the rig use; ``flagtrack config check`` collects them as notes).

    Raises:
        ConfigError: naming the key and the rig file.
    """
    from flagtrack.daemon.rig.certificates import check_certificates

    findings = findings if findings is not None else Findings()
    for spec in in_table_order(list(services)):
        if spec.check is not None:
            spec.check(rig, findings)
    check_certificates(rig, services, findings)
    return findings


PLACEHOLDER_HOST = re.compile(r"[A-Z][A-Z0-9_]*_HOST")
"""A host written as a word for the lab to replace (``ROUTER_HOST`` in the two-host examples)."""


def check_endpoints(rig: RigConfig, findings: Findings) -> None:
    """Note a bus endpoint whose host is still a placeholder (Zenoh's own error names its source file):
    for the commands that open the rig's bus, and ``config check``."""
    bus = rig.bus_config
    for name in ("connect", "listen"):
        for i, endpoint in enumerate(getattr(bus, name)):
            address = re.split(r"[#?]", endpoint.partition("/")[2], maxsplit=1)[0]  # (without #iface=... ?...)
            host = address.rpartition(":")[0] or address
            if PLACEHOLDER_HOST.fullmatch(host):
                text = f"{endpoint}: {host} is a placeholder; put the host's name or address there"
                findings.note(text, key=f"bus.{name}[{i}]", path=rig.path)
