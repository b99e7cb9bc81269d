"""The secured two-host example: the rig loads, its zenohd config is the one `flagtrack router` makes
from it (and Zenoh takes it), and the systemd units are hardened (systemd-analyze, where it exists)."""

from __future__ import annotations

import argparse
import json
import re
import shutil
import subprocess
from pathlib import Path

import pytest
import zenoh

from flagtrack.daemon.commands.router import router_config, zenohd_config
from flagtrack.daemon.rig.config import load_rig
from flagtrack.daemon.transport import zenoh_settings

DEPLOY = Path(__file__).resolve().parents[2] / "deploy"
UNITS = DEPLOY / "systemd"


def test_the_secured_rig_and_its_zenohd_config_agree() -> None:
    rig = load_rig(DEPLOY / "rig-secure.yaml", services=())
    assert rig.bus_config.secured and rig.bus_config.access_control is not None
    args = argparse.Namespace(config=DEPLOY / "rig-secure.yaml", listen=[], connect=[])
    want = zenohd_config(zenoh_settings(router_config(args), check_files=False))
    text = (DEPLOY / "zenoh-router-secure.json5").read_text()
    got = json.loads("\n".join(line for line in text.splitlines() if not line.startswith("//")))
    assert got == want, "regenerate: flagtrack router -c deploy/rig-secure.yaml --zenohd-config"
    assert got["listen"]["endpoints"] == ["tls/ROUTER_HOST:7447"] == list(rig.bus_config.connect)
    config = zenoh.Config.from_json5(text)  # Zenoh's own parser takes it
    assert json.loads(config.get_json("access_control/default_permission")) == "deny"
    assert json.loads(config.get_json("transport/link/tls/enable_mtls")) is True


def unit_settings(path: Path) -> dict[str, list[str]]:
    settings: dict[str, list[str]] = {}
    for line in path.read_text().splitlines():
        if "=" in line and not line.startswith("#"):
            key, value = line.split("=", 1)
            settings.setdefault(key.strip(), []).append(value.strip())
    return settings


def test_the_units_are_hardened() -> None:
    unit = unit_settings(UNITS / "flagtrack@.service")
    for key, value in {
        "NoNewPrivileges": "yes",
        "ProtectSystem": "strict",
        "ProtectHome": "yes",
        "PrivateTmp": "yes",
        "CapabilityBoundingSet": "",
        "DevicePolicy": "closed",
        "User": "flagtrack-%i",
    }.items():
        assert unit[key] == [value], key
    assert unit["ReadWritePaths"] == ["/var/lib/flagtrack"]
    assert set(unit["RestrictAddressFamilies"][0].split()) == {"AF_UNIX", "AF_INET", "AF_INET6", "AF_NETLINK"}
    assert {c.split(":")[0] for c in unit["LoadCredential"]} == {"ca", "cert", "key"}
    assert "DeviceAllow" not in unit  # only the instances that need a device get one
    allowed = {path.parent.name: unit_settings(path)["DeviceAllow"] for path in UNITS.glob("*.service.d/devices.conf")}
    assert allowed == {
        "flagtrack@camera.service.d": ["char-usb_device rw"],
        "flagtrack@supervisor.service.d": ["/dev/flagtrack-tunnel rw"],
        "flagtrack@sensor.service.d": ["/dev/flagtrack-sensor rw"],
    }
    assert not any("DeviceAllow" in unit_settings(path) for path in UNITS.glob("*.service.d/[!d]*.conf"))


def test_the_units_tell_systemd_they_are_alive() -> None:
    """Type=notify with a watchdog (READY/WATCHDOG from the services' loops, daemon/services/sd_notify.py);
    the supervisor's allows for one blocking tunnel step (ramp + settle timeout)."""
    unit = unit_settings(UNITS / "flagtrack@.service")
    assert unit["Type"] == ["notify"] and unit["NotifyAccess"] == ["main"]
    assert unit["WatchdogSec"] == ["30"] and unit["Restart"] == ["on-failure"]
    supervisor = unit_settings(UNITS / "flagtrack@supervisor.service.d" / "watchdog.conf")
    assert supervisor["WatchdogSec"] == ["120"]


@pytest.mark.skipif(shutil.which("systemd-analyze") is None, reason="systemd-analyze is not installed here")
@pytest.mark.parametrize("instance", ["router", "camera", "supervisor", "recorder"])
def test_systemd_analyze_rates_each_unit_ok(tmp_path: Path, instance: str) -> None:
    system = tmp_path / "etc" / "systemd" / "system"
    shutil.copytree(UNITS, system)
    result = subprocess.run(
        ["systemd-analyze", "security", "--offline=yes", f"--root={tmp_path}", f"flagtrack@{instance}.service"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    exposure = re.search(r"Overall exposure level for \S+: ([0-9.]+)", result.stdout)
    assert exposure is not None, result.stdout + result.stderr
    assert float(exposure.group(1)) <= 2.0  # "OK"; the units of before: 9.2, "UNSAFE"
