"""``flagtrack certs init|issue|check``: the private CA and the identities of a secured bus."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

COMMAND = "certs"
HELP = "make and check the certificates of a secured bus (a private CA, one identity per service)"
DESCRIPTION = """\
Certificates for mutual TLS on the bus (bus.security.tls): `init` makes a private CA and one
identity per service, `issue` adds or renews one, `check` says what expires when (exit 1 when
something must be renewed). More: docs/security.md, docs/commands.md.
"""
DEFAULT_IDENTITIES = "camera,tracker,recorder,viewer,supervisor,sensor,operator,router"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Subcommands of ``flagtrack certs``."""
    from flagtrack.daemon.security.cert_days import CA_DAYS, LEAF_DAYS, WARN_DAYS

    sub = parser.add_subparsers(dest="certs_command", metavar="ACTION", required=True)
    init = sub.add_parser(
        "init",
        help="a new CA and one certificate per identity",
        description="Make a new certificate authority in DIR and one key and certificate per identity, for a "
        "bus secured with mutual TLS (docs/security.md).",
    )
    init.add_argument("directory", type=Path, metavar="DIR")
    init.add_argument(
        "--identities", default=DEFAULT_IDENTITIES, help=f"comma-separated identities (default {DEFAULT_IDENTITIES})"
    )
    init.add_argument("--ca-days", type=int, default=CA_DAYS, help=f"validity of the CA, days (default {CA_DAYS})")
    issue = sub.add_parser(
        "issue",
        help="issue (or with --replace renew) one identity's key and certificate",
        description="Issue one identity's key and certificate from the CA in DIR; --replace renews one that "
        "exists, with a new key (docs/security.md).",
    )
    issue.add_argument("directory", type=Path, metavar="DIR")
    issue.add_argument("name", metavar="NAME")
    issue.add_argument("--replace", action="store_true", help="renew an identity that exists (a new key too)")
    for p in (init, issue):
        p.add_argument(
            "--host",
            action="append",
            default=[],
            metavar="NAME_OR_ADDRESS",
            help="a host name or address the certificate names (repeatable; default localhost and 127.0.0.1)",
        )
        p.add_argument("--days", type=int, default=LEAF_DAYS, help=f"validity, days (default {LEAF_DAYS})")
    check = sub.add_parser(
        "check",
        help="what expires when; non-zero exit if something must be renewed",
        description="Say when the CA and each certificate in DIR expire; exit non-zero if one must be renewed "
        "within --within-days (docs/security.md).",
    )
    check.add_argument("directory", type=Path, metavar="DIR")
    check.add_argument(
        "--within-days",
        type=float,
        default=WARN_DAYS,
        help=f"fail for certificates that expire within this many days (default {WARN_DAYS})",
    )


def run(args: argparse.Namespace) -> int:
    """Carry out ``init``, ``issue`` or ``check``."""
    from flagtrack.daemon.security import certs

    hosts = tuple(getattr(args, "host", None) or certs.DEFAULT_HOSTS)
    if args.certs_command == "init":
        names = [name.strip() for name in args.identities.split(",") if name.strip()]
        infos = certs.init(args.directory, names, hosts=hosts, ca_days=args.ca_days, days=args.days)
        print(
            f"CA {infos[0].path} (key {args.directory / certs.CA_KEY}: keep it apart), valid to {infos[0].not_after:%Y-%m-%d}"
        )
        for info in infos[1:]:
            print(
                f"  {info.common_name}: {info.path}, {info.path.with_suffix('.key')}, valid to {info.not_after:%Y-%m-%d}"
            )
        return 0
    if args.certs_command == "issue":
        info = certs.issue(args.directory, args.name, hosts=hosts, days=args.days, replace=args.replace)
        verb = "renewed" if args.replace else "issued"
        print(
            f"{verb} {info.common_name}: {info.path}, {info.path.with_suffix('.key')}, valid to "
            f"{info.not_after:%Y-%m-%d}, names {', '.join(info.hosts) or '-'}"
        )
        return 0
    results = certs.check(args.directory, within_days=args.within_days)
    bad = [r for r in results if r.problem]
    for result in results:
        info = result.info
        kind = "CA" if info.is_ca else "identity"
        state = result.problem or "ok"
        print(
            f"{info.path.name:20s} {kind:8s} {info.common_name:24s} expires {info.not_after:%Y-%m-%d} "
            f"({info.days_left():6.0f} days)  {state}"
        )
    if bad:
        listed = ", ".join(f"{r.info.path.name} ({r.problem})" for r in bad)
        print(f"flagtrack certs check: {len(bad)} to act on: {listed}", file=sys.stderr)
        return 1
    return 0
