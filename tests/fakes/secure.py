"""Helpers for tests of the secured bus: certificates made with ``flagtrack certs``' code, rig files whose
bus is (or is not) secured, a router in this process, and Zenoh sessions of intruders built by hand."""

from __future__ import annotations

import dataclasses
import datetime as dt
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import zenoh

from flagtrack.daemon.rig.config import RigConfig, load_rig
from flagtrack.daemon.security import certs
from flagtrack.daemon.transport import BusConfig

IDENTITIES = ("camera", "tracker", "recorder", "viewer", "supervisor", "sensor", "operator", "router")


@dataclass(frozen=True)
class Pki:
    """The rig's certificate folder, another CA's, and an identity of the rig's CA that has expired."""

    rig: Path
    other: Path

    @property
    def ca(self) -> Path:
        return self.rig / "ca.pem"


def make_pki(folder: Path) -> Pki:
    """A CA with every identity (``IDENTITIES``), a second CA with the same names, and ``expired``
    (the rig's CA, valid for one day three days ago)."""
    certs.init(folder / "rig", IDENTITIES)
    certs.init(folder / "other", IDENTITIES)
    certs.issue(folder / "rig", "expired", days=1, now=dt.datetime.now(dt.UTC) - dt.timedelta(days=3))
    return Pki(folder / "rig", folder / "other")


def rig_text(port: int, pki: Pki | None, *, acl: bool = True, body: str = "", rig: str = "sec") -> str:
    """A rig file whose services are clients of a router on 127.0.0.1:``port``: mutual TLS with one
    identity per process and (``acl``) the rig's access control, or plain TCP (``pki`` None)."""
    if pki is None:
        bus = f'bus: {{mode: client, connect: ["tcp/127.0.0.1:{port}"]}}\n'
    else:
        bus = (
            "bus:\n  mode: client\n"
            f'  connect: ["tls/127.0.0.1:{port}"]\n'
            "  security:\n"
            f'    tls: {{ca: "{pki.ca}", cert: "{pki.rig}/{{identity}}.pem", key: "{pki.rig}/{{identity}}.key"}}\n'
            f"    acl: {str(acl).lower()}\n"
            "    operators: [operator]\n"
        )
    return f"rig: {rig}\n{bus}{body}"


def load(path: Path, text: str) -> RigConfig:
    path.write_text(text)
    return load_rig(path, services=())


def router_config(rig: RigConfig, port: int) -> BusConfig:
    """The router of ``rig`` listening on 127.0.0.1:``port`` (as ``flagtrack router -c`` makes it)."""
    bus = rig.bus_config_for([], identity="router")
    scheme = "tls" if bus.secured else "tcp"
    return dataclasses.replace(bus, mode="router", listen=(f"{scheme}/127.0.0.1:{port}",), connect=())


def intruder_config(
    port: int,
    *,
    ca: Path | None,
    cert: Path | None = None,
    key: Path | None = None,
    scheme: str = "tls",
    mode: str = "peer",
) -> zenoh.Config:
    """A Zenoh session that joins 127.0.0.1:``port`` with whatever it holds (built by hand, not by
    flagtrack's checks): trusting ``ca``, presenting ``cert``/``key`` if given."""
    config = zenoh.Config()
    config.insert_json5("mode", json.dumps(mode))
    config.insert_json5("scouting/multicast/enabled", "false")
    config.insert_json5("connect/endpoints", json.dumps([f"{scheme}/127.0.0.1:{port}"]))
    tls: dict[str, Any] = {}
    if ca is not None:
        tls["root_ca_certificate"] = str(ca)
    if cert is not None:
        tls.update(connect_certificate=str(cert), connect_private_key=str(key), enable_mtls=True)
    if tls:
        config.insert_json5("transport/link/tls", json.dumps(tls))
    return config
