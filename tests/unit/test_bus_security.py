"""The `bus.security` section: tls/ endpoints only, an identity per process, rules made from the rig's
keys, no password in records, and identifiers that cannot leave their folder or widen a key."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from flagtrack.daemon.errors import ConfigError
from flagtrack.daemon.rig.access import access_control, identity_rights
from flagtrack.daemon.rig.config import RigConfig, load_rig
from flagtrack.daemon.schema import Keys
from flagtrack.daemon.security import certs
from flagtrack.daemon.security.acl import describe
from flagtrack.daemon.security.config import REDACTED, SecurityConfig, TlsFiles
from flagtrack.daemon.transport import zenoh_settings
from flagtrack.daemon.typed_yaml import from_mapping


def secured_rig(tmp_path: Path, bus: str = "", extra: str = "") -> Path:
    folder = tmp_path / "certs"
    if not folder.exists():
        certs.init(folder, ["camera", "tracker", "analysis", "router"])
    path = tmp_path / "rig.yaml"
    path.write_text(f"""
rig: lab1
camera: {{id: cam7}}
bus:
  mode: client
  connect: ["tls/127.0.0.1:7447"]
  security:
    tls: {{ca: {folder}/ca.pem, cert: "{folder}/{{identity}}.pem", key: "{folder}/{{identity}}.key"}}
    acl: true
    operators: [operator]
    identities: {{analysis: [tracker, recorder, viewer]}}
{bus}
{extra}""")
    return path


@pytest.mark.parametrize(
    ("bus", "key"),
    [
        ('  listen: ["tcp/127.0.0.1:7448"]\n', "bus.listen[0]"),
        ('  connect: ["tls/127.0.0.1:7447", "tcp/127.0.0.1:7447"]\n', "bus.connect[1]"),
    ],
)
def test_a_secured_bus_refuses_tcp_endpoints_naming_the_key(tmp_path: Path, bus: str, key: str) -> None:
    path = secured_rig(tmp_path)
    text = path.read_text().replace('  connect: ["tls/127.0.0.1:7447"]\n', bus)
    path.write_text(text)
    with pytest.raises(ConfigError) as info:
        load_rig(path, services=())
    assert info.value.key == key and str(path) in str(info.value) and "tls/" in str(info.value)


def test_each_process_presents_its_own_identity(tmp_path: Path) -> None:
    rig = load_rig(secured_rig(tmp_path), services=())
    tls = zenoh_settings(rig.bus_config_for(["camera"]))["transport/link/tls"]
    assert tls["connect_certificate"].endswith("/camera.pem") and tls["enable_mtls"] is True
    assert tls["root_ca_certificate"].endswith("/ca.pem") and tls["close_link_on_expiration"] is True
    with pytest.raises(ConfigError, match="name the identity") as info:
        zenoh_settings(rig.bus_config_for(["tracker", "recorder"]))
    assert info.value.key == "bus.security.identity"
    several = zenoh_settings(rig.bus_config_for(["tracker", "recorder"], identity="analysis"))
    assert several["transport/link/tls"]["listen_private_key"].endswith("/analysis.key")
    with pytest.raises(ConfigError, match="no such file"):  # no certificate for this one in the folder
        zenoh_settings(rig.bus_config_for(["viewer"]))


def test_the_rules_are_made_from_the_rigs_keys(tmp_path: Path) -> None:
    rig = load_rig(secured_rig(tmp_path), services=())
    control = rig.bus_config.access_control
    assert control is not None and control["enabled"] and control["default_permission"] == "deny"
    keys = Keys("flagtrack/lab1")
    rules = {rule["id"]: rule for rule in control["rules"]}
    assert rules["camera-publish"]["key_exprs"] == [
        keys.camera_events("cam7"),
        keys.event_rate("cam7"),
        keys.camera_status("cam7"),
    ]
    assert rules["camera-publish"]["messages"] == ["put"] and rules["camera-publish"]["flows"] == ["ingress"]
    assert rules["tracker-subscribe"]["key_exprs"] == [keys.camera_events("cam7")]
    assert set(rules["supervisor-publish"]["key_exprs"]) == {
        keys.supervisor_state(),
        keys.tunnel_state(),
        keys.recorder_command(),
        keys.speed_reply(),
    }
    assert "viewer-publish" not in rules  # a viewer only looks
    assert set(rules["operator-publish"]["key_exprs"]) == {
        keys.recorder_command(),
        keys.tunnel_command(),
        keys.speed_request("operator"),  # its own request key only: the key says who asks
    }
    analysis = set(rules["analysis-subscribe"]["key_exprs"])
    assert {keys.camera_events("cam7"), keys.centrelines(), keys.recorder_command()} <= analysis
    assert rules["recorder-token"]["key_exprs"] == [keys.alive("recorder")]
    subjects = {s["id"]: s["cert_common_names"] for s in control["subjects"]}
    assert subjects["subject-viewer"] == ["viewer"] and subjects["subject-router"] == ["router"]
    lines = describe(control)
    assert (
        f"camera: put ingress {keys.camera_events('cam7')} {keys.event_rate('cam7')} {keys.camera_status('cam7')}"
        in lines
    )
    # no service may publish another's keys: one owner per key, commands apart
    owners: dict[str, set[str]] = {}
    security = rig.bus_config.security
    assert security is not None
    for name, rights in identity_rights(keys, security, ["cam7"], []).items():
        for key in rights.publish if name != "analysis" else ():
            owners.setdefault(key, set()).add(name)
    assert owners[keys.recorder_command()] == {"supervisor", "operator"}
    assert all(len(names) == 1 for key, names in owners.items() if key != keys.recorder_command())
    json.dumps(control)  # what Zenoh is given


def test_the_password_never_reaches_a_record(tmp_path: Path) -> None:
    path = secured_rig(tmp_path, bus="    user: rig\n    password: hunter2-secret\n")
    assert path.read_text().count("hunter2-secret") == 1  # (it was given twice: the YAML loader refuses that now)
    rig = load_rig(path, services=())
    assert "hunter2" not in repr(rig.bus)
    snapshot = rig.snapshot()
    assert "hunter2" not in json.dumps(snapshot) and snapshot["bus"]["security"]["password"] == REDACTED
    assert snapshot["bus"]["security"]["tls"]["key"].endswith("{identity}.key")  # paths only
    assert zenoh_settings(rig.bus_config_for(["camera"]))["transport/auth/usrpwd"] == {
        "user": "rig",
        "password": "hunter2-secret",
    }
    with pytest.raises(ConfigError, match="redacted") as info:  # a stored record cannot stand for the rig
        from_mapping(RigConfig, snapshot)
    assert info.value.key == "bus.security.password"


def test_a_password_file_must_be_private(tmp_path: Path) -> None:
    secret = tmp_path / "password"
    secret.write_text("s3cret\n")
    os.chmod(secret, 0o644)
    security = SecurityConfig(user="rig", password_file=secret)
    with pytest.raises(ConfigError, match="chmod 600"):
        security.read_password()
    os.chmod(secret, 0o600)
    assert security.read_password() == "s3cret"
    with pytest.raises(ConfigError, match="needs a user"):
        SecurityConfig(password="x")
    with pytest.raises(ConfigError, match="needs tls"):
        SecurityConfig(acl=True)
    with pytest.raises(ConfigError, match="identity") as info:
        SecurityConfig(tls=TlsFiles(Path("ca"), Path("c"), Path("k")), operators=("Op erator",))
    assert info.value.key == "bus.security.operators[0]"


def test_the_rules_are_not_a_key_of_the_rig_file(tmp_path: Path) -> None:
    path = tmp_path / "rig.yaml"
    path.write_text("bus: {access_control: {enabled: false}}\n")
    with pytest.raises(ConfigError, match="made from the rig") as info:
        load_rig(path, services=())
    assert info.value.key == "bus.access_control"


@pytest.mark.parametrize(
    ("text", "key"),
    [
        ("camera: {id: ../cam}\n", "camera.id"),
        ("camera: {id: 'cam 0'}\n", "camera.id"),
        ("camera: {id: 'cam/*'}\n", "camera.id"),
        ("rig: '~root'\n", "rig"),
        ("rig: ..\n", "rig"),
        ("sensor: {id: '..', driver: simulated}\n", "sensor.id"),
        ("supervisor: {run_name: ../../etc}\n", "supervisor.run_name"),
        ("bus: {namespace: 'flagtrack/**'}\n", "bus.namespace"),
    ],
)
def test_names_that_become_file_names_or_keys_are_checked_when_read(tmp_path: Path, text: str, key: str) -> None:
    path = tmp_path / "rig.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError) as info:
        load_rig(path, services=())
    assert info.value.key == key and str(path) in str(info.value), str(info.value)


def test_usual_names_still_load(tmp_path: Path) -> None:
    path = tmp_path / "rig.yaml"
    path.write_text("rig: Lab_1.b\ncamera: {id: cam0}\nsupervisor: {run_name: run-20261121-101500}\n")
    assert load_rig(path, services=()).bus_config.namespace == "flagtrack/Lab_1.b"


def test_rules_for_a_sensor_and_its_samples(tmp_path: Path) -> None:
    security = SecurityConfig(tls=TlsFiles(Path("ca"), Path("c"), Path("k")), acl=True)
    control = access_control(Keys("flagtrack/s"), security, ["cam0"], ["om70"])
    rules = {rule["id"]: rule for rule in control["rules"]}
    assert rules["sensor-publish"]["key_exprs"] == ["flagtrack/s/sensor/om70/samples"]
    assert "flagtrack/s/sensor/om70/samples" in rules["supervisor-subscribe"]["key_exprs"]
    assert rules["sensor-token"]["key_exprs"] == ["flagtrack/s/alive/sensor/om70"]


def test_a_password_of_another_type_is_refused_without_being_printed(tmp_path: Path) -> None:
    path = secured_rig(tmp_path)
    path.write_text(
        path.read_text().replace("    acl: true\n", "    acl: true\n    user: rig\n    password: 98765432\n")
    )
    with pytest.raises(ConfigError, match="quote it") as info:
        load_rig(path, services=())
    assert "98765432" not in str(info.value) and info.value.key == "bus.security.password"
