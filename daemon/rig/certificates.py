"""The certificates the processes of a secured rig present (``bus.security.tls``), checked as the bus
checks them when it opens (:func:`~flagtrack.daemon.security.config.zenoh_security`: the CA, each
identity's certificate signed by it, in its validity period, naming that identity, and its private key),
before any host runs the rig."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

from flagtrack.daemon.errors import ConfigError
from flagtrack.daemon.rig.findings import Findings
from flagtrack.daemon.rig.sections import RigSections
from flagtrack.daemon.security.cert_days import WARN_DAYS


def presented_identities(rig: RigSections, services: Sequence[str]) -> list[str]:
    """The identities the processes running ``services`` present: ``bus.security.identity`` when it is
    given (one process), else each service's own name (each runs alone: ``flagtrack camera -c``)."""
    security = rig.bus.security if rig.bus is not None else None
    if security is None or security.tls is None:
        return []
    return [security.identity] if security.identity else list(services)


def check_certificates(rig: RigSections, services: Sequence[str], findings: Findings) -> None:
    """Check each presented identity's files (config check only: strict, the bus checks its own when it
    opens); warn of one that expires within the renewal window.

    Raises:
        ConfigError: a file missing or wrong, naming the key, the identity and the rig file.
    """
    security = rig.bus.security if rig.bus is not None else None
    if findings.strict or not findings.files or security is None or security.tls is None:
        return
    from flagtrack.daemon.security.certs import cert_info  # cryptography: for a secured bus only
    from flagtrack.daemon.security.config import zenoh_security

    listens = bool(rig.bus is not None and rig.bus.listen)
    for identity in presented_identities(rig, services):
        try:
            zenoh_security(dataclasses.replace(security, identity=identity), listens=listens)
        except ConfigError as exc:
            prefix = f"key '{exc.key}': " if exc.key else ""
            message = str(exc).removeprefix(prefix)
            raise ConfigError(f"identity {identity!r}: {message}", key=exc.key, path=rig.path) from None
        cert = security.tls.for_identity(identity).cert
        days = cert_info(cert).days_left()
        if days < WARN_DAYS:
            findings.warn(
                f"{cert} ({identity}) expires in {days:.0f} days: renew it (flagtrack certs issue DIR {identity} --replace)",
                key="bus.security.tls.cert",
            )
