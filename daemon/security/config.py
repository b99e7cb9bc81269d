"""The ``bus.security`` section of a rig: mutual TLS, Zenoh user/password, access control.

Example (``deploy/rig-secure.yaml``)::

    bus:
      mode: client
      connect: ["tls/router.lab:7447"]
      security:
        tls:
          ca: /etc/flagtrack/certs/ca.pem
          cert: /etc/flagtrack/certs/{identity}.pem     # {identity}: the one this process presents
          key: /etc/flagtrack/certs/{identity}.key
        acl: true                                       # default deny; rules made from the rig
        operators: [operator]                           # may also send recorder and tunnel commands, ask for speeds

A process presents one identity (the common name of its certificate): ``identity`` if given, else
the service it runs (``flagtrack camera`` presents ``camera``), ``router`` for ``flagtrack router``.
A process that runs several services (``flagtrack up``) names its identity, and ``identities`` says
which services' rights it has. The password is never logged and never written into records
(:meth:`SecurityConfig.redacted`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from flagtrack.daemon.errors import ConfigError
from flagtrack.daemon.security.files import require_private
from flagtrack.daemon.security.names import identity_problem

REDACTED = "<redacted>"
"""What records hold instead of a password."""
ROUTER = "router"
"""The identity of ``flagtrack router`` (and of zenohd with deploy/zenoh-router-secure.json5)."""


@dataclass(frozen=True)
class TlsFiles:
    """``bus.security.tls``: the CA every peer's certificate must be signed by, and this process's own.

    Attributes:
        ca: the CA certificate (PEM); every link's other end must hold a certificate it signed.
        cert, key: this process's certificate and private key (PEM); ``{identity}`` in any of the
            three is replaced by the process's identity, so one rig file serves every service of a host.
        verify_name: check that a listener's certificate names the host or address connected to
            (``flagtrack certs issue --host``); off, any certificate of the CA is taken.
    """

    ca: Path
    cert: Path
    key: Path
    verify_name: bool = True

    def for_identity(self, identity: str) -> TlsFiles:
        """The files with ``{identity}`` filled in."""
        return dataclasses.replace(
            self,
            ca=Path(str(self.ca).replace("{identity}", identity)),
            cert=Path(str(self.cert).replace("{identity}", identity)),
            key=Path(str(self.key).replace("{identity}", identity)),
        )


@dataclass(frozen=True)
class SecurityConfig:
    """``bus.security``.

    Attributes:
        tls: mutual TLS on every link (every endpoint of ``bus.listen`` and ``bus.connect`` must be
            ``tls/``); None: no TLS (then neither ``acl`` nor ``identity`` means anything).
        identity: the identity this process presents (default: the one service it runs).
        identities: identity -> the services whose rights it has, for identities that are not a
            service's name (``analysis: [tracker, recorder, viewer]`` for ``flagtrack up`` on one host;
            the rig checks the names against its services).
        operators: identities that may in addition send recorder and tunnel commands, ask for wind
            speeds (on their own request key), and read every key.
        acl: enforce access-control rules made from the rig (default deny).
        user, password, password_file: Zenoh user/password authentication of this process (a
            password in the file is better than in the rig file; either is redacted from records).
        users_file: the ``user:password`` lines a listening process (a router) accepts.
    """

    tls: TlsFiles | None = None
    identity: str | None = None
    identities: dict[str, tuple[str, ...]] = field(default_factory=dict)
    operators: tuple[str, ...] = ()
    acl: bool = False
    user: str | None = None
    password: str | None = field(default=None, repr=False)
    password_file: Path | None = None
    users_file: Path | None = None

    def __post_init__(self) -> None:
        if self.password == REDACTED:
            raise ConfigError(
                "the password was redacted from this record: give the rig file (-c) or a password_file",
                key="bus.security.password",
            )
        if (self.password is not None or self.password_file is not None) and not self.user:
            raise ConfigError("a password needs a user", key="bus.security.user")
        if self.password is not None and self.password_file is not None:
            raise ConfigError("give password or password_file, not both", key="bus.security.password")
        if self.acl and self.tls is None:
            raise ConfigError("access control tells identities apart by certificate: needs tls", key="bus.security.acl")
        named = [(f"bus.security.operators[{i}]", name) for i, name in enumerate(self.operators)]
        named += [(f"bus.security.identities.{name}", name) for name in self.identities]
        if self.identity is not None:
            named.append(("bus.security.identity", self.identity))
        for key, name in named:
            problem = identity_problem(name)
            if problem is not None:
                raise ConfigError(problem, key=key)

    def redacted(self) -> SecurityConfig:
        """This section as records may hold it: the password replaced by :data:`REDACTED` (paths stay)."""
        if self.password is None:
            return self
        return _replace_unchecked(self, password=REDACTED)

    def secrets(self) -> tuple[str, ...]:
        """The password, as far as it can be read (to take it out of error messages)."""
        try:
            password = self.read_password()
        except ConfigError:
            password = None
        return (password,) if password else ()

    def read_password(self) -> str | None:
        """The password (from ``password_file`` if given; its first line).

        Raises:
            ConfigError: the file cannot be read, is empty or others may read it.
        """
        if self.password_file is None:
            return self.password
        path = Path(self.password_file).expanduser()
        require_private(path, key="bus.security.password_file")
        try:
            lines = path.read_text().splitlines()
        except OSError as exc:
            raise ConfigError(f"cannot read {path}: {exc.strerror}", key="bus.security.password_file") from exc
        if not lines or not lines[0]:
            raise ConfigError(f"{path} is empty", key="bus.security.password_file")
        return lines[0]


def _replace_unchecked(obj: Any, **changes: Any) -> Any:
    """A copy of frozen dataclass ``obj`` with ``changes``, without running its checks."""
    copy = object.__new__(type(obj))
    for f in dataclasses.fields(obj):
        object.__setattr__(copy, f.name, changes.get(f.name, getattr(obj, f.name)))
    return copy


def zenoh_security(security: SecurityConfig, *, listens: bool, check_files: bool = True) -> dict[str, Any]:
    """The Zenoh settings (config path -> value) of ``bus.security`` for a session; ``listens``: it
    accepts links (a router, a listening peer), so it checks the users of ``users_file``.

    With ``check_files`` (not when writing a config for another host) the files are checked first, so a mistake is one line naming its key rather than a failed
    handshake: the CA, this identity's certificate (common name = the identity, signed by the CA, in
    its validity period) and key (its own, mode 0600).

    Raises:
        ConfigError: no identity to present, or a file that is missing, wrong or readable by others.
    """
    settings: dict[str, Any] = {}
    if security.tls is not None:
        if security.identity is None:
            raise ConfigError(
                "this process runs several services: name the identity it presents (its certificate's common name)",
                key="bus.security.identity",
            )
        tls = security.tls.for_identity(security.identity)
        if check_files:
            from flagtrack.daemon.security.certs import check_identity_files  # cryptography: for a secured bus only

            check_identity_files(tls.ca, tls.cert, tls.key, security.identity)
        settings["transport/link/tls"] = {
            "root_ca_certificate": str(tls.ca),
            "listen_certificate": str(tls.cert),
            "listen_private_key": str(tls.key),
            "connect_certificate": str(tls.cert),
            "connect_private_key": str(tls.key),
            "enable_mtls": True,
            "verify_name_on_connect": tls.verify_name,
            "close_link_on_expiration": True,
        }
    usrpwd: dict[str, Any] = {}
    if security.user:
        usrpwd["user"] = security.user
        password = security.read_password() if check_files or security.password_file is None else None
        if password is not None:
            usrpwd["password"] = password
    if security.users_file is not None and listens:
        users = Path(security.users_file).expanduser()
        usrpwd["dictionary_file"] = str(require_private(users, key="bus.security.users_file") if check_files else users)
    if usrpwd:
        settings["transport/auth/usrpwd"] = usrpwd
    return settings
