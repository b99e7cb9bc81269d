"""`flagtrack certs`: a private CA apart from the identities, keys only their owner reads, names that
cannot leave their folder, and a check that names what expired or expires soon."""

from __future__ import annotations

import datetime as dt
import os
import stat
import subprocess
import sys
from pathlib import Path

import pytest
from cryptography import x509
from cryptography.x509.oid import ExtendedKeyUsageOID, NameOID

from flagtrack.daemon.errors import ConfigError
from flagtrack.daemon.security import certs

NOW = dt.datetime.now(dt.UTC)


def mode(path: Path) -> int:
    return stat.S_IMODE(path.stat().st_mode)


def flagtrack(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "flagtrack.daemon", *args], capture_output=True, text=True, timeout=60)


def test_init_makes_a_ca_apart_and_one_private_key_per_identity(tmp_path: Path) -> None:
    folder = tmp_path / "certs"
    infos = certs.init(folder, ["camera", "tracker", "operator"])
    assert [i.common_name for i in infos[1:]] == ["camera", "tracker", "operator"]
    assert (folder / "ca.pem").is_file() and not (folder / "ca.key").exists()
    assert mode(folder / "ca" / "ca.key") == 0o600 and mode(folder / "ca") == 0o700
    for name in ("camera", "tracker", "operator"):
        assert mode(folder / f"{name}.key") == 0o600
        cert = x509.load_pem_x509_certificate((folder / f"{name}.pem").read_bytes())
        assert cert.subject.get_attributes_for_oid(NameOID.COMMON_NAME)[0].value == name
        cert.verify_directly_issued_by(x509.load_pem_x509_certificate((folder / "ca.pem").read_bytes()))
        usages = cert.extensions.get_extension_for_class(x509.ExtendedKeyUsage).value
        assert {ExtendedKeyUsageOID.SERVER_AUTH, ExtendedKeyUsageOID.CLIENT_AUTH} <= set(usages)
        days = (cert.not_valid_after_utc - cert.not_valid_before_utc).days
        assert 365 <= days <= 2 * 366  # 1-2 years for an identity
    ca = certs.cert_info(folder / "ca.pem")
    assert ca.is_ca and 9 * 365 < (ca.not_after - ca.not_before).days <= 10 * 366
    assert infos[1].hosts == ("localhost", "127.0.0.1")


def test_a_key_is_0600_whatever_the_umask(tmp_path: Path) -> None:
    old = os.umask(0)
    try:
        certs.init(tmp_path / "c", ["camera"])
    finally:
        os.umask(old)
    assert mode(tmp_path / "c" / "camera.key") == 0o600 and mode(tmp_path / "c" / "ca" / "ca.key") == 0o600


@pytest.mark.parametrize("name", ["../evil", "Camera", "cam/0", "", "a" * 33, "-x", "ca", "x.y", "~root"])
def test_names_that_cannot_be_file_names_or_common_names_are_refused(tmp_path: Path, name: str) -> None:
    certs.init(tmp_path / "c", [])
    with pytest.raises(ConfigError, match="identity"):
        certs.issue(tmp_path / "c", name)
    assert sorted(p.name for p in (tmp_path / "c").iterdir()) == ["ca", "ca.pem"]  # nothing written


def test_issue_refuses_to_overwrite_unless_renewing(tmp_path: Path) -> None:
    certs.init(tmp_path / "c", ["camera"])
    old_key = (tmp_path / "c" / "camera.key").read_bytes()
    with pytest.raises(ConfigError, match="--replace"):
        certs.issue(tmp_path / "c", "camera")
    info = certs.issue(tmp_path / "c", "camera", replace=True, hosts=["router.lab", "192.0.2.10"])
    assert (tmp_path / "c" / "camera.key").read_bytes() != old_key and info.hosts == ("router.lab", "192.0.2.10")
    with pytest.raises(ConfigError, match="already has a CA"):
        certs.init(tmp_path / "c", ["tracker"])


def test_check_names_what_expired_expires_soon_or_is_not_this_cas(tmp_path: Path) -> None:
    folder = tmp_path / "c"
    certs.init(folder, ["camera", "tracker"])
    certs.issue(folder, "old", days=1, now=NOW - dt.timedelta(days=3))
    certs.issue(folder, "soon", days=10)
    certs.init(tmp_path / "other", ["stranger"])
    for suffix in (".pem", ".key"):
        (folder / f"stranger{suffix}").write_bytes((tmp_path / "other" / f"stranger{suffix}").read_bytes())
    os.chmod(folder / "stranger.key", 0o600)
    os.chmod(folder / "tracker.key", 0o644)
    problems = {c.info.common_name: c.problem for c in certs.check(folder, within_days=30)}
    assert problems["camera"] == "" and problems[certs.cert_info(folder / "ca.pem").common_name] == ""
    assert problems["old"].startswith("expired on")
    assert "expires on" in problems["soon"] and "in 10 days" in problems["soon"]
    assert "not signed by" in problems["stranger"]
    assert "readable by others" in problems["tracker"]


def test_the_command_exits_non_zero_naming_what_to_renew(tmp_path: Path) -> None:
    folder = tmp_path / "c"
    made = flagtrack("certs", "init", str(folder), "--identities", "camera,operator")
    assert made.returncode == 0, made.stderr
    assert "camera" in made.stdout and (folder / "operator.key").is_file()
    ok = flagtrack("certs", "check", str(folder))
    assert ok.returncode == 0 and ok.stdout.count(" ok") == 3, ok.stdout
    certs.issue(folder, "old", days=1, now=NOW - dt.timedelta(days=3))
    late = flagtrack("certs", "check", str(folder))
    assert late.returncode == 1 and "old.pem (expired on" in late.stderr
    soon = flagtrack("certs", "check", str(folder), "--within-days", "1000")
    assert soon.returncode == 1 and "camera.pem (expires on" in soon.stderr
    bad = flagtrack("certs", "issue", str(folder), "../x")
    assert bad.returncode == 2 and "identity '../x'" in bad.stderr and len(bad.stderr.strip().splitlines()) == 1


def test_identity_files_are_checked_before_zenoh_reads_them(tmp_path: Path) -> None:
    folder = tmp_path / "c"
    certs.init(folder, ["camera", "viewer"])
    certs.issue(folder, "old", days=1, now=NOW - dt.timedelta(days=3))
    certs.init(tmp_path / "other", ["camera"])
    ca = folder / "ca.pem"
    certs.check_identity_files(ca, folder / "camera.pem", folder / "camera.key", "camera")
    cases = [
        ((ca, folder / "viewer.pem", folder / "viewer.key", "camera"), "certificate of 'viewer'"),
        ((ca, folder / "old.pem", folder / "old.key", "old"), "expired"),
        ((ca, tmp_path / "other" / "camera.pem", tmp_path / "other" / "camera.key", "camera"), "not issued by"),
        ((ca, folder / "camera.pem", folder / "viewer.key", "camera"), "not the certificate's"),
        ((tmp_path / "nope.pem", folder / "camera.pem", folder / "camera.key", "camera"), "no such file"),
    ]
    for args, words in cases:
        with pytest.raises(ConfigError, match=words):
            certs.check_identity_files(*args)
    os.chmod(folder / "camera.key", 0o640)
    with pytest.raises(ConfigError, match="tls.key.*chmod 600"):
        certs.check_identity_files(ca, folder / "camera.pem", folder / "camera.key", "camera")


def test_a_ca_bundle_takes_either_cas_identities_while_rotating(tmp_path: Path) -> None:
    """Rotating the CA: ca.pem holds the old and the new CA until every identity is reissued."""
    certs.init(tmp_path / "old", ["camera"])
    certs.init(tmp_path / "new", ["camera"])
    bundle = tmp_path / "bundle.pem"
    bundle.write_bytes((tmp_path / "old" / "ca.pem").read_bytes() + (tmp_path / "new" / "ca.pem").read_bytes())
    for folder in ("old", "new"):
        certs.check_identity_files(bundle, tmp_path / folder / "camera.pem", tmp_path / folder / "camera.key", "camera")
    with pytest.raises(ConfigError, match="not issued by"):
        certs.check_identity_files(
            tmp_path / "old" / "ca.pem", tmp_path / "new" / "camera.pem", tmp_path / "new" / "camera.key", "camera"
        )
