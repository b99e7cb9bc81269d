"""The service table says each service once: its rights on the bus (the access-control rules are made from
it), its name everywhere a service is named, and how it is built, which opens nothing."""

from __future__ import annotations

import dataclasses
import threading
from pathlib import Path
from typing import Any

import pytest

from flagtrack.daemon.commands import services as service_commands
from flagtrack.daemon.errors import ConfigError
from flagtrack.daemon.rig.access import access_control, expand_keys, service_rights, spec_rights
from flagtrack.daemon.rig.build import build_services
from flagtrack.daemon.rig.config import RigConfig
from flagtrack.daemon.rig.table import SERVICE_NAMES, SERVICES
from flagtrack.daemon.schema import Keys
from flagtrack.daemon.security.acl import Rights
from flagtrack.daemon.security.config import SecurityConfig, TlsFiles
from flagtrack.daemon.typed_yaml import from_mapping

CAMERAS, SENSORS = ("cam0", "cam1"), ("om70",)


def test_each_services_rights_are_the_keys_its_entry_names() -> None:
    """Written out key by key (as the rules were before the table): two cameras, one sensor."""
    k = Keys("flagtrack/lab")
    events = (k.camera_events("cam0"), k.camera_events("cam1"))
    rates = (k.event_rate("cam0"), k.event_rate("cam1"))
    assert service_rights(k, CAMERAS, SENSORS) == {
        "supervisor": Rights(
            publish=(k.supervisor_state(), k.tunnel_state(), k.recorder_command(), k.speed_reply()),
            subscribe=(
                *rates,
                k.centrelines(),
                k.recorder_status(),
                k.tunnel_command(),
                k.sensor_samples("om70"),
                k.flag_state(),
                k.speed_requests(),
            ),
            tokens=(k.alive("supervisor"),),
            watch=True,
        ),
        "flagstate": Rights(
            publish=(k.flag_state(),), subscribe=(k.centrelines(), k.tunnel_state()), tokens=(k.alive("flagstate"),)
        ),
        "recorder": Rights(
            publish=(k.recorder_status(),),
            subscribe=(*events, k.centrelines(), k.recorder_command()),
            tokens=(k.alive("recorder"),),
        ),
        "tracker": Rights(
            publish=(k.centrelines(), k.tracker_status()), subscribe=events, tokens=(k.alive("tracker"),)
        ),
        "viewer": Rights(
            subscribe=(k.centrelines(), *events, *rates, k.tunnel_state(), k.supervisor_state()),
            tokens=(k.alive("viewer"),),
        ),
        "sensor": Rights(publish=(k.sensor_samples("om70"),), tokens=(k.alive("sensor/om70"),)),
        "camera": Rights(
            publish=(*events, *rates, k.camera_status("cam0"), k.camera_status("cam1")),
            subscribe=(k.tunnel_state(),),
            tokens=(k.alive("camera/cam0"), k.alive("camera/cam1")),
        ),
    }


def test_the_access_control_rules_are_what_the_table_derives() -> None:
    keys = Keys("flagtrack/lab")
    security = SecurityConfig(
        tls=TlsFiles(Path("ca"), Path("c"), Path("k")),
        acl=True,
        identities={"analysis": ("tracker", "recorder", "viewer")},
        operators=("operator",),
    )
    control = access_control(keys, security, CAMERAS, SENSORS)
    rules = {rule["id"]: rule["key_exprs"] for rule in control["rules"]}
    for spec in SERVICES:
        publish = list(expand_keys(keys, spec.publishes, CAMERAS, SENSORS))
        subscribe = list(expand_keys(keys, spec.subscribes, CAMERAS, SENSORS))
        assert rules.get(f"{spec.name}-publish", []) == publish == rules.get(f"{spec.name}-publish-interest", [])
        assert rules.get(f"{spec.name}-subscribe", []) == subscribe == rules.get(f"{spec.name}-receive", [])
        assert rules[f"{spec.name}-token"] == list(spec_rights(keys, spec, CAMERAS, SENSORS).tokens)
        assert (f"{spec.name}-watch" in rules) == spec.watches
    # an identity of several services has the union of theirs, and nothing more
    wanted = set()
    for spec in SERVICES:
        if spec.name in ("tracker", "recorder", "viewer"):
            wanted |= set(expand_keys(keys, spec.subscribes, CAMERAS, SENSORS))
    assert set(rules["analysis-subscribe"]) == wanted and keys.tunnel_command() not in wanted


def test_a_service_is_named_in_the_table_only() -> None:
    assert sorted(command.COMMAND for command in service_commands.COMMANDS) == sorted(SERVICE_NAMES)
    assert [command.HELP for command in service_commands.COMMANDS] == [spec.help for spec in SERVICES]
    with pytest.raises(
        ConfigError, match=f"unknown service 'radar' in services \\(known: {', '.join(SERVICE_NAMES)}\\)"
    ):
        from_mapping(RigConfig, {"services": ["camera", "radar"]})
    security = {"identities": {"analysis": ["tracker", "radar"]}}
    with pytest.raises(ConfigError, match="bus.security.identities.analysis.*unknown service 'radar'"):
        from_mapping(RigConfig, {"bus": {"namespace": "flagtrack/x", "security": security}})
    sections = {field.name for field in dataclasses.fields(RigConfig)}
    for spec in SERVICES:
        assert set(spec.needs) <= set(spec.sections) <= sections, spec.name
        for section in spec.needs:
            with pytest.raises(ConfigError, match=f"the {spec.name} service needs a '{section}:' section"):
                from_mapping(RigConfig, {"services": [spec.name]})


class Untouchable:
    """A bus that records any use (a constructor must not subscribe, publish or even read the keys)."""

    def __init__(self) -> None:
        self.touched: list[str] = []

    def __getattr__(self, name: str) -> Any:
        self.touched.append(name)
        raise AssertionError(f"a constructor used the bus: {name}")


def test_building_every_service_opens_nothing(tmp_path: Path) -> None:
    """All six, with a simulated tunnel (opening it would start a pseudo-terminal and a thread), the
    recorder's, viewer's and supervisor's folders not there yet: nothing made, nothing started."""
    rig = from_mapping(
        RigConfig,
        {
            "camera": {"adapter": "simulated"},
            "tracker": {"root": [150, 240], "length": 300},
            "recorder": {"directory": str(tmp_path / "rec"), "path": "run"},
            "viewer": {"sink": "rrd", "rrd_path": str(tmp_path / "view" / "live.rrd")},
            "tunnel": {"driver": "simulated"},
            "supervisor": {"runs_dir": str(tmp_path / "runs")},
            "sensor": {"driver": "simulated"},
            "services": list(SERVICE_NAMES),
        },
    )
    bus = Untouchable()
    threads = threading.active_count()
    services = build_services(rig, bus, SERVICE_NAMES)  # type: ignore[arg-type]
    assert [s.name.split("/")[0] for s in services] == list(SERVICE_NAMES)  # in table order
    assert bus.touched == [] and list(tmp_path.iterdir()) == [] and threading.active_count() == threads
    assert services[0].tunnel is None  # type: ignore[attr-defined]  # opened by start(), not before
