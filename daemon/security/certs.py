"""A private certificate authority and one key and certificate per identity, for mutual TLS on the bus.

Layout of a certificate folder ``DIR`` (``flagtrack certs init DIR``)::

    DIR/ca.pem               the CA certificate (public: every host gets a copy)
    DIR/ca/ca.key            the CA's private key (mode 0600 in a 0700 folder; keep it off the rig's hosts)
    DIR/<identity>.pem       the identity's certificate (common name = the identity), signed by the CA
    DIR/<identity>.key       its private key (mode 0600; readable by its service alone)

Keys are ECDSA P-256, signatures SHA-256 (what rustls, Zenoh's TLS, takes). Every identity's
certificate serves both ends of a link (``serverAuth`` and ``clientAuth``): a peer both listens and
connects, a router listens. Its subject alternative names are the host names and addresses others
use to reach it (``hosts``; by default ``localhost`` and ``127.0.0.1``), which Zenoh checks when it
connects (``bus.security.tls.verify_name``). Written with the ``cryptography`` library only.
"""

from __future__ import annotations

import datetime as dt
import ipaddress
import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

from cryptography import x509
from cryptography.exceptions import InvalidSignature
from cryptography.hazmat.primitives import hashes, serialization
from cryptography.hazmat.primitives.asymmetric import ec
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from flagtrack.daemon.errors import ConfigError
from flagtrack.daemon.security.cert_days import CA_DAYS, LEAF_DAYS, WARN_DAYS
from flagtrack.daemon.security.files import require_private
from flagtrack.daemon.security.names import IDENTITY_RE, identity_problem
from flagtrack.drivers.atomic import atomic_write

DEFAULT_HOSTS = ("localhost", "127.0.0.1")
CA_CERT = "ca.pem"
CA_KEY = Path("ca") / "ca.key"
RESERVED = frozenset({"ca"})  # ca.pem is the CA's


def _utc_now() -> dt.datetime:
    return dt.datetime.now(dt.UTC)


def _write_private(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` created with mode 0600 (never readable by others, even for an instant)."""
    atomic_write(path, data, permissions=0o600)


def _write_public(path: Path, data: bytes) -> None:
    atomic_write(path, data, permissions=0o644)


def _key_pem(key: ec.EllipticCurvePrivateKey) -> bytes:
    return key.private_bytes(
        serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8, serialization.NoEncryption()
    )


def _san(hosts: Iterable[str]) -> x509.SubjectAlternativeName:
    names: list[x509.GeneralName] = []
    for host in hosts:
        try:
            names.append(x509.IPAddress(ipaddress.ip_address(host)))
        except ValueError:
            names.append(x509.DNSName(host))
    return x509.SubjectAlternativeName(names)


def check_identity(name: str) -> str:
    """``name`` if it can be an identity (its file names and certificate common name).

    Raises:
        ConfigError: not a valid identity name, or a reserved one (``ca``).
    """
    problem = identity_problem(name)
    if problem is None and name in RESERVED:
        problem = f"identity {name!r} is reserved ({name}.pem is the CA's certificate)"
    if problem is not None:
        raise ConfigError(problem)
    return name


@dataclass(frozen=True)
class CertInfo:
    """What a certificate file says: its common name, validity (UTC), issuer and file."""

    path: Path
    common_name: str
    not_before: dt.datetime
    not_after: dt.datetime
    issuer: str
    is_ca: bool
    hosts: tuple[str, ...] = ()

    def days_left(self, now: dt.datetime | None = None) -> float:
        """Days until it expires (negative: expired that long ago)."""
        return (self.not_after - (now or _utc_now())).total_seconds() / 86400.0


def read_certificate(path: Path) -> x509.Certificate:
    """The first certificate of a PEM file.

    Raises:
        ConfigError: unreadable, or not a PEM certificate.
    """
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise ConfigError(f"cannot read certificate {path}: {exc.strerror}") from exc
    try:
        return x509.load_pem_x509_certificate(data)
    except ValueError as exc:
        raise ConfigError(f"{path} is not a PEM certificate ({exc})") from exc


def read_authorities(path: Path) -> list[x509.Certificate]:
    """Every certificate of a CA file (a bundle of the old and the new CA while rotating, see docs/security.md).

    Raises:
        ConfigError: unreadable, or no PEM certificate in it.
    """
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise ConfigError(f"cannot read certificate {path}: {exc.strerror}") from exc
    try:
        return x509.load_pem_x509_certificates(data)
    except ValueError as exc:
        raise ConfigError(f"{path} holds no PEM certificate ({exc})") from exc


def issued_by_any(cert: x509.Certificate, authorities: list[x509.Certificate]) -> bool:
    """Whether one of ``authorities`` signed ``cert``."""
    for ca in authorities:
        try:
            cert.verify_directly_issued_by(ca)
            return True
        except (ValueError, TypeError, InvalidSignature):
            continue
    return False


def cert_info(path: Path) -> CertInfo:
    """Read a certificate file's common name, validity, issuer and names."""
    cert = read_certificate(path)
    names = cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)
    issuer = cert.issuer.get_attributes_for_oid(NameOID.COMMON_NAME)
    try:
        is_ca = bool(cert.extensions.get_extension_for_class(x509.BasicConstraints).value.ca)
    except x509.ExtensionNotFound:
        is_ca = False
    try:
        san = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
        hosts = tuple([*san.get_values_for_type(x509.DNSName), *map(str, san.get_values_for_type(x509.IPAddress))])
    except x509.ExtensionNotFound:
        hosts = ()
    return CertInfo(
        Path(path),
        str(names[0].value) if names else "",
        cert.not_valid_before_utc,
        cert.not_valid_after_utc,
        str(issuer[0].value) if issuer else "",
        is_ca,
        hosts,
    )


def init_ca(
    directory: Path, *, name: str | None = None, days: int = CA_DAYS, now: dt.datetime | None = None
) -> CertInfo:
    """Make a new CA in ``directory``: ``ca.pem`` and, apart, ``ca/ca.key`` (0600, folder 0700).

    Raises:
        ConfigError: the folder already has a CA (rotating one is deliberate: use another folder).
    """
    directory = Path(directory)
    if (directory / CA_CERT).exists() or (directory / CA_KEY).exists():
        raise ConfigError(f"{directory} already has a CA ({CA_CERT}); make a new one in another folder to rotate it")
    if days < 1:
        raise ConfigError(f"a CA valid for {days} days makes no sense")
    start = now or _utc_now()
    key = ec.generate_private_key(ec.SECP256R1())
    subject = x509.Name(
        [
            x509.NameAttribute(NameOID.ORGANIZATION_NAME, "flagtrack"),
            x509.NameAttribute(NameOID.COMMON_NAME, name or f"flagtrack CA {directory.resolve().name}"[:64]),
        ]
    )
    ski = x509.SubjectKeyIdentifier.from_public_key(key.public_key())
    cert = (
        x509.CertificateBuilder()
        .subject_name(subject)
        .issuer_name(subject)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(start - dt.timedelta(minutes=5))  # a host whose clock is a little behind
        .not_valid_after(start + dt.timedelta(days=days))
        .add_extension(x509.BasicConstraints(ca=True, path_length=0), critical=True)
        .add_extension(
            x509.KeyUsage(
                digital_signature=False,
                content_commitment=False,
                key_encipherment=False,
                data_encipherment=False,
                key_agreement=False,
                key_cert_sign=True,
                crl_sign=True,
                encipher_only=False,
                decipher_only=False,
            ),
            critical=True,
        )
        .add_extension(ski, critical=False)
        .sign(key, hashes.SHA256())
    )
    (directory / CA_KEY).parent.mkdir(parents=True, exist_ok=True)
    os.chmod(directory, os.stat(directory).st_mode & 0o7755)  # no one else may write here
    os.chmod(directory / CA_KEY.parent, 0o700)
    _write_private(directory / CA_KEY, _key_pem(key))
    _write_public(directory / CA_CERT, cert.public_bytes(serialization.Encoding.PEM))
    return cert_info(directory / CA_CERT)


def _load_ca(directory: Path) -> tuple[x509.Certificate, ec.EllipticCurvePrivateKey]:
    cert = read_certificate(directory / CA_CERT)
    try:
        key = serialization.load_pem_private_key((directory / CA_KEY).read_bytes(), password=None)
    except OSError as exc:
        raise ConfigError(
            f"cannot read the CA key {directory / CA_KEY}: {exc.strerror} (issue certificates where the CA key is)"
        ) from exc
    if not isinstance(key, ec.EllipticCurvePrivateKey):
        raise ConfigError(f"{directory / CA_KEY} is not an EC key")
    return cert, key


def issue(
    directory: Path,
    name: str,
    *,
    hosts: Sequence[str] = DEFAULT_HOSTS,
    days: int = LEAF_DAYS,
    now: dt.datetime | None = None,
    replace: bool = False,
) -> CertInfo:
    """Issue identity ``name`` a new key (``DIR/<name>.key``, 0600) and certificate (``DIR/<name>.pem``,
    common name ``name``, names ``hosts``) signed by the CA of ``directory``.

    Args:
        replace: renew an identity that has a certificate already (a new key too).
        now: the start of the validity (tests make expired certificates with a past one).

    Raises:
        ConfigError: a bad name, no CA here, or the identity exists and ``replace`` is false.
    """
    directory = Path(directory)
    check_identity(name)
    if days < 1:
        raise ConfigError(f"a certificate valid for {days} days makes no sense")
    cert_path, key_path = directory / f"{name}.pem", directory / f"{name}.key"
    if not replace and (cert_path.exists() or key_path.exists()):
        raise ConfigError(f"identity {name!r} exists in {directory} (renew it with --replace)")
    ca_cert, ca_key = _load_ca(directory)
    start = now or _utc_now()
    key = ec.generate_private_key(ec.SECP256R1())
    builder = (
        x509.CertificateBuilder()
        .subject_name(
            x509.Name(
                [
                    x509.NameAttribute(NameOID.ORGANIZATION_NAME, "flagtrack"),
                    x509.NameAttribute(NameOID.COMMON_NAME, name),
                ]
            )
        )
        .issuer_name(ca_cert.subject)
        .public_key(key.public_key())
        .serial_number(x509.random_serial_number())
        .not_valid_before(start - dt.timedelta(minutes=5))
        .not_valid_after(start + dt.timedelta(days=days))
        .add_extension(x509.BasicConstraints(ca=False, path_length=None), critical=True)
        .add_extension(
            x509.KeyUsage(
                digital_signature=True,
                content_commitment=False,
                key_encipherment=False,
                data_encipherment=False,
                key_agreement=False,
                key_cert_sign=False,
                crl_sign=False,
                encipher_only=False,
                decipher_only=False,
            ),
            critical=True,
        )
        .add_extension(x509.ExtendedKeyUsage([ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH]), False)
        .add_extension(x509.SubjectKeyIdentifier.from_public_key(key.public_key()), critical=False)
        .add_extension(x509.AuthorityKeyIdentifier.from_issuer_public_key(ca_key.public_key()), critical=False)
    )
    if hosts:
        builder = builder.add_extension(_san(hosts), critical=False)
    cert = builder.sign(ca_key, hashes.SHA256())
    _write_private(key_path, _key_pem(key))
    _write_public(cert_path, cert.public_bytes(serialization.Encoding.PEM))
    return cert_info(cert_path)


def init(
    directory: Path,
    identities: Sequence[str],
    *,
    hosts: Sequence[str] = DEFAULT_HOSTS,
    ca_days: int = CA_DAYS,
    days: int = LEAF_DAYS,
    now: dt.datetime | None = None,
) -> list[CertInfo]:
    """A new CA in ``directory`` and one certificate per identity (names checked before anything is written)."""
    for name in identities:
        check_identity(name)
    if len(set(identities)) != len(identities):
        raise ConfigError("an identity is named twice")
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    infos = [init_ca(directory, days=ca_days, now=now)]
    infos += [issue(directory, name, hosts=hosts, days=days, now=now) for name in identities]
    return infos


@dataclass(frozen=True)
class CertCheck:
    """One certificate's state: ``problem`` says what is wrong (expired, expires soon, another CA,
    a key that does not match, a key others can read), empty when nothing is."""

    info: CertInfo
    problem: str = ""
    warning: str = ""


def _key_matches(cert: x509.Certificate, key_path: Path) -> str:
    """Why the private key at ``key_path`` is not ``cert``'s (or readable by others), or ''."""
    try:
        mode = key_path.stat().st_mode & 0o777
        key = serialization.load_pem_private_key(key_path.read_bytes(), password=None)
    except OSError as exc:
        return f"cannot read its key {key_path.name}: {exc.strerror}"
    except (ValueError, TypeError) as exc:
        return f"its key {key_path.name} is not a PEM private key ({exc})"
    if mode & 0o077:
        return f"its key {key_path.name} is readable by others (mode {mode:o}; chmod 600)"
    wanted = cert.public_key().public_bytes(serialization.Encoding.DER, serialization.PublicFormat.SubjectPublicKeyInfo)
    got = key.public_key().public_bytes(serialization.Encoding.DER, serialization.PublicFormat.SubjectPublicKeyInfo)
    return "" if wanted == got else f"its key {key_path.name} is not the certificate's"


def check(directory: Path, *, within_days: float = WARN_DAYS, now: dt.datetime | None = None) -> list[CertCheck]:
    """Every certificate of ``directory``: the CA first, then the identities by name.

    An identity's certificate has a problem when it has expired or expires within ``within_days``,
    was not signed by this folder's CA, names another identity than its file, or its key (if present
    here) is not its own or is readable by others. A missing key is not a problem (each host keeps
    only its own).

    Raises:
        ConfigError: no ``ca.pem`` in the folder.
    """
    directory = Path(directory)
    now = now or _utc_now()
    ca_path = directory / CA_CERT
    if not ca_path.is_file():
        raise ConfigError(f"no {CA_CERT} in {directory} (make one with flagtrack certs init)")
    authorities = read_authorities(ca_path)
    results = [_expiry(cert_info(ca_path), within_days, now)]
    for path in sorted(directory.glob("*.pem")):
        if path.name == CA_CERT or IDENTITY_RE.fullmatch(path.stem) is None:
            continue
        cert = read_certificate(path)
        info = cert_info(path)
        result = _expiry(info, within_days, now)
        problems = [result.problem] if result.problem else []
        if not issued_by_any(cert, authorities):
            problems.append(f"not signed by {ca_path}")
        if info.common_name != path.stem:
            problems.append(f"its common name is {info.common_name!r}, not {path.stem!r}")
        key_path = path.with_suffix(".key")
        if key_path.exists():
            mismatch = _key_matches(cert, key_path)
            if mismatch:
                problems.append(mismatch)
        results.append(CertCheck(info, "; ".join(problems), result.warning))
    return results


def _expiry(info: CertInfo, within_days: float, now: dt.datetime) -> CertCheck:
    left = info.days_left(now)
    if left < 0:
        return CertCheck(info, f"expired on {info.not_after:%Y-%m-%d %H:%M} UTC ({-left:.0f} days ago)")
    if left < within_days:
        return CertCheck(info, f"expires on {info.not_after:%Y-%m-%d} UTC, in {left:.0f} days (renew it)")
    if info.not_before > now:
        return CertCheck(info, f"not valid before {info.not_before:%Y-%m-%d %H:%M} UTC (a clock is wrong)")
    return CertCheck(info)


def check_identity_files(
    ca_path: Path, cert_path: Path, key_path: Path, identity: str, now: dt.datetime | None = None
) -> None:
    """Check what a process will present on a secured bus before Zenoh reads it: the CA certificate,
    the identity's certificate (common name ``identity``, signed by the CA, valid now) and its key
    (the certificate's, mode 0600).

    Raises:
        ConfigError: naming the key of ``bus.security.tls`` and the problem.
    """
    now = now or _utc_now()
    for key, path in (("ca", ca_path), ("cert", cert_path)):
        if not Path(path).is_file():
            raise ConfigError(f"no such file: {path}", key=f"bus.security.tls.{key}")
    try:
        authorities = read_authorities(ca_path)
        cert = read_certificate(cert_path)
    except ConfigError as exc:
        raise ConfigError(str(exc), key="bus.security.tls") from None
    info = cert_info(cert_path)
    where = "bus.security.tls.cert"
    if info.common_name != identity:
        raise ConfigError(
            f"{cert_path} is the certificate of {info.common_name!r}; this process presents {identity!r}", key=where
        )
    if not issued_by_any(cert, authorities):
        raise ConfigError(f"{cert_path} was not issued by the CA of {ca_path}", key=where)
    if info.days_left(now) < 0:
        raise ConfigError(f"{cert_path} expired on {info.not_after:%Y-%m-%d %H:%M} UTC (renew it)", key=where)
    if info.not_before > now:
        raise ConfigError(f"{cert_path} is not valid before {info.not_before:%Y-%m-%d %H:%M} UTC", key=where)
    require_private(Path(key_path), key="bus.security.tls.key")
    mismatch = _key_matches(cert, Path(key_path))
    if mismatch:
        raise ConfigError(f"{cert_path}: {mismatch}", key="bus.security.tls.key")
