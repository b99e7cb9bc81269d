"""How a notebook or a script joins a rig's bus: from the rig's file, or from an endpoint.

A client never listens: it connects to where the rig listens (``bus.listen`` of a rig that runs as
one process, an address ``0.0.0.0`` becoming this host's loopback) or to the rig's router
(``bus.connect``). On a secured bus it presents its own identity (its certificate's common name,
``bus.security.identity`` of its rig file or ``identity=``); to ask for wind speeds that identity
must be one of the rig's ``bus.security.operators``.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

from flagtrack.daemon.errors import ConfigError
from flagtrack.daemon.security.config import SecurityConfig, TlsFiles
from flagtrack.daemon.security.names import identifier_problem
from flagtrack.daemon.transport import BusConfig
from flagtrack.daemon.typed_yaml import from_mapping, load_yaml

DEFAULT_IDENTITY = "client"
"""The identity a client names itself by on a plain bus when none is given (not authenticated)."""


def rig_bus(path: str | Path) -> BusConfig:
    """The bus section of the rig file ``path`` (namespace ``flagtrack/<rig>`` unless it says one).

    Raises:
        ConfigError: the file cannot be read, or its ``rig`` or ``bus`` section is wrong (key and file named).
    """
    data = load_yaml(path)
    rig = data.get("rig", "default")
    problem = identifier_problem(rig, "the name") if isinstance(rig, str) else "the rig's name must be a word"
    if problem is not None:
        raise ConfigError(problem, key="rig", path=str(path))
    bus = data.get("bus") or {}
    if not isinstance(bus, dict):
        raise ConfigError("must be a mapping", key="bus", path=str(path))
    return from_mapping(BusConfig, {"namespace": f"flagtrack/{rig}", **bus}, path=str(path), key="bus")


def client_bus(rig: BusConfig, identity: str | None = None) -> BusConfig:
    """The bus of a client of the rig whose bus is ``rig``: connected to where the rig listens (or
    to its router), listening nowhere, presenting ``identity`` (default: the section's own).

    Raises:
        ConfigError: the rig's bus names nowhere to connect to (it runs in one process with no
            ``bus.listen``), or a secured bus with no identity to present.
    """
    endpoints = rig.connect or tuple(_reachable(e) for e in rig.listen)
    if not endpoints:
        raise ConfigError(
            "the rig's bus has no endpoint a client can reach: give it bus.listen (e.g. "
            "[tcp/127.0.0.1:7447]) or run it through a router (bus.connect)",
            key="bus.listen",
        )
    security = rig.security
    if security is not None:
        security = dataclasses.replace(security, identity=identity or security.identity, users_file=None)
        if security.tls is not None and security.identity is None:
            raise ConfigError("name the identity this client presents (its certificate)", key="bus.security.identity")
    return dataclasses.replace(
        rig, mode="peer", listen=(), connect=tuple(endpoints), security=security, access_control=None
    )


def endpoint_bus(
    endpoint: str,
    namespace: str,
    *,
    ca: str | Path | None = None,
    cert: str | Path | None = None,
    key: str | Path | None = None,
    identity: str | None = None,
) -> BusConfig:
    """The bus of a client connecting to ``endpoint`` (``tcp/HOST:PORT``, or ``tls/HOST:PORT`` with
    the CA, this client's certificate and key) under ``namespace`` (``flagtrack/<rig>``).

    Raises:
        ConfigError: a ``tls/`` endpoint without its files or identity, or files without a ``tls/`` endpoint.
    """
    tls: Any = None
    if endpoint.startswith("tls/"):
        if ca is None or cert is None or key is None or identity is None:
            raise ConfigError("a tls/ endpoint needs ca, cert, key and identity", key="endpoint")
        tls = TlsFiles(Path(ca), Path(cert), Path(key))
    elif any(v is not None for v in (ca, cert, key)):
        raise ConfigError("certificates are for a tls/ endpoint", key="endpoint")
    security = SecurityConfig(tls=tls, identity=identity) if tls is not None else None
    return BusConfig(namespace=namespace, mode="peer", connect=(endpoint,), security=security)


def identity_of(bus: BusConfig) -> str:
    """The identity a client on ``bus`` asks in the name of."""
    if bus.security is not None and bus.security.identity is not None:
        return bus.security.identity
    return DEFAULT_IDENTITY


def _reachable(endpoint: str) -> str:
    """A listening endpoint as a client on this host reaches it (any address: loopback)."""
    for anywhere, here in (("0.0.0.0", "127.0.0.1"), ("[::]", "[::1]")):
        endpoint = endpoint.replace(f"/{anywhere}:", f"/{here}:")
    return endpoint
