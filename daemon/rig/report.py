"""A rig file checked whole, opening no device, and what it would run (``flagtrack config check``).

The checks are the rig's own (:func:`~.config.load_rig`: keys, types, ranges; :func:`~.config.check_rig`:
each service's check of the service table, the certificates of a secured bus), with what this host
lacks collected as notes (:class:`~.findings.Findings`) rather than raised. A file with ``services:``
is a rig: its services are checked, and the supervisor too when it holds a sweep plan (``flagtrack
sweep -c`` adds it). A file without is a part of one (``deploy/tunnel-ascii.yaml``): the services
whose own section it holds are checked, and its tunnel.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from flagtrack.daemon.errors import ConfigError
from flagtrack.daemon.rig.config import RigConfig, check_endpoints, check_rig, load_rig
from flagtrack.daemon.rig.describe import DESCRIPTIONS, bus_line, disk_line, tunnel_line
from flagtrack.daemon.rig.findings import Findings, Note
from flagtrack.daemon.rig.host import check_port
from flagtrack.daemon.rig.plan import PlanEstimate, estimate_plan
from flagtrack.daemon.rig.table import SERVICE_NAMES, SERVICES, in_table_order
from flagtrack.daemon.typed_yaml import load_yaml

READING_ORDER = ("camera", "tracker", "flagstate", "recorder", "viewer", "sensor", "supervisor")
"""The order of the summary's lines: along the data, then what drives the tunnel."""


@dataclass(frozen=True)
class RigReport:
    """What ``flagtrack config check`` found.

    Attributes:
        path: the file.
        kind: ``rig`` (it has ``services:``) or ``part`` (sections of a rig).
        services: the services checked, in table order.
        runs: the commands that would run it, each with what they run.
        lines: (what, one line about it), in order: the bus, the services, the tunnel.
        plan: the sweep plan's estimate, if it has one.
        notes: what this host lacks, and warnings.
        files: whether this host's files, folders, ports and SDKs were looked at.
    """

    path: str
    kind: str
    services: tuple[str, ...]
    runs: tuple[str, ...]
    lines: tuple[tuple[str, str], ...]
    plan: PlanEstimate | None
    notes: tuple[Note, ...] = field(default=())
    files: bool = True


def check_rig_file(
    path: str | Path, *, services: Sequence[str] | None = None, files: bool = True, strict: bool = False
) -> RigReport:
    """Check the rig file ``path`` whole, opening no device and creating nothing.

    Args:
        services: the services this host runs (default: the file's, with the supervisor if it has a
            sweep plan; a part's: those whose section it holds).
        files: look at this host's files, folders, ports and SDKs (off: a config for another host).
        strict: a note (what the host lacks) is an error.

    Raises:
        ConfigError: one line naming the key and the file.
    """
    data = load_yaml(path)
    if not data:  # (it passed as "a part of a rig", --strict too: a file saved empty, or the wrong one)
        raise ConfigError("holds no sections: nothing to check (a rig: deploy/rig-single-pc.yaml)", path=str(path))
    rig = load_rig(path, services=())
    kind = "rig" if "services" in data else "part"
    names = _chosen_services(rig, data, services)
    findings = Findings(strict=False, files=files)
    check_endpoints(rig, findings)
    check_rig(rig, names, findings)
    if rig.tunnel is not None and "supervisor" not in names and rig.tunnel.driver != "simulated":
        check_port(rig.tunnel.port, key="tunnel.port", what="the tunnel's controller", findings=findings)
    pending = [note for note in findings.notes if note.pending]
    if strict and pending:
        more = [note.key or "?" for note in pending[1:]]
        rest = f"; {len(more)} more to do: {', '.join(more)}" if more else ""
        raise ConfigError(f"{pending[0].text} (--strict{rest})", key=pending[0].key, path=str(path))
    lines = [("bus", bus_line(rig))] if kind == "rig" or "bus" in data else []
    lines += [(name, DESCRIPTIONS[name](rig)) for name in READING_ORDER if name in names]
    if rig.tunnel is not None:
        lines.append(("tunnel", tunnel_line(rig)))
    disk = disk_line(rig, names) if files else None
    if disk is not None:
        lines.append(("disk", disk))
    plan = estimate_plan(rig) if "supervisor" in names else None
    runs = _runs(rig, str(path), kind, names)
    return RigReport(str(path), kind, tuple(names), runs, tuple(lines), plan, tuple(findings.notes), files)


def _chosen_services(rig: RigConfig, data: dict, services: Sequence[str] | None) -> list[str]:
    if services is not None:
        unknown = [name for name in services if name not in SERVICE_NAMES]
        if unknown:
            raise ConfigError(f"unknown service {unknown[0]!r} (known: {', '.join(SERVICE_NAMES)})", key="--services")
        return [spec.name for spec in in_table_order(services)]
    if "services" not in data:  # a part: the services whose own section it holds
        return [spec.name for spec in SERVICES if spec.sections[0] in data]
    names = list(rig.services)
    if rig.supervisor.sweep is not None and "supervisor" not in names:
        names.append("supervisor")  # what `flagtrack sweep -c` runs
    return [spec.name for spec in in_table_order(names)]


def _runs(rig: RigConfig, path: str, kind: str, names: Sequence[str]) -> tuple[str, ...]:
    """The commands that run the file, each with what it runs."""
    if kind == "part":
        readers = []
        if rig.tunnel is not None:
            readers.append(f"flagtrack tunnel get|set|stop -c {path} (its tunnel:)")
        if rig.tracker.root is not None:
            readers.append(f"flagtrack reconstruct REC -o OUT.h5 -c {path} (its tracker:)")
        return (*readers, "a part of a rig (no services:): put its sections in a rig file to run them")
    security = rig.bus.security if rig.bus is not None else None
    alone = security is not None and security.tls is not None and not security.identity
    up = [name for name in rig.services]
    runs = []
    if alone and len(up) > 1:  # each presents its own certificate: one process per service
        runs.append(
            "each service alone (a secured bus, no bus.security.identity): "
            + ", ".join(f"flagtrack {name} -c {path}" for name in up)
        )
    else:
        runs.append(f"flagtrack up -c {path}: {', '.join(up)}")
    if rig.supervisor.sweep is not None and "supervisor" in names:
        sweeping = (
            "the supervisor also sweeps whenever it starts (mode sweep; a restart resumes)"
            if ("supervisor" in up and rig.supervisor.mode == "sweep")
            else "the same services and the supervisor, which runs the plan"
        )
        runs.append(f"flagtrack sweep -c {path}: {sweeping}")
    return tuple(runs)
