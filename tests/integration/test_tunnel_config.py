"""The ``tunnel`` config section and the deploy/tunnel-*.yaml examples."""

from __future__ import annotations

from pathlib import Path

import pytest

from flagtrack.daemon.errors import ConfigError
from flagtrack.daemon.rig.config import load_rig
from flagtrack.daemon.sweep.plan import Record, sweep_plan
from flagtrack.drivers.tunnel.setup import TunnelConfig, load_tunnel_config
from tests.conftest import REPO

DEPLOY = REPO / "deploy"


@pytest.mark.parametrize(("name", "driver"), [("tunnel-ascii.yaml", "ascii"), ("tunnel-modbus.yaml", "modbus"),
                                              ("tunnel-sim.yaml", "simulated")])  # fmt: skip
def test_deploy_examples_load(name: str, driver: str) -> None:
    cfg = load_tunnel_config(DEPLOY / name)
    assert cfg.driver == driver
    assert cfg.safety.keepalive_s <= cfg.safety.watchdog_s / 2


def test_deploy_ascii_example_is_the_default_protocol() -> None:
    assert load_tunnel_config(DEPLOY / "tunnel-ascii.yaml").ascii == TunnelConfig().ascii


def test_deploy_sweep_example_is_the_papers_loop() -> None:
    cfg = load_rig(DEPLOY / "rig-single-pc.yaml", services=()).supervisor.sweep
    assert cfg is not None
    records = [s for s in sweep_plan(cfg) if isinstance(s, Record)]
    assert len(records) == 45 and cfg.speed_values()[0] == 3.0 and cfg.speed_values()[-1] == 8.5


@pytest.mark.parametrize(
    ("body", "key", "words"),
    [
        ("tunnel:\n  driver: ascii\n", "tunnel", "needs a port"),
        ("tunnel:\n  driver: serial\n", "tunnel.driver", "one of"),
        ("tunnel:\n  safety: {keepalive_s: 4, watchdog_s: 5}\n", "tunnel.safety", "at most half"),
        ("tunnel:\n  modbus: {control: relay}\n", "tunnel.modbus.control", "one of"),
        ("tunnel:\n  sim: {tau_s: 0}\n", "tunnel.sim", "tau_s must be positive"),
        ("tunnel:\n  sim: {watchdog_s: 1}\n", "tunnel", "half of sim.watchdog_s"),
        ("camera: {}\n", "tunnel", "section is missing"),
    ],
)
def test_config_errors_name_key_and_file(tmp_path: Path, body: str, key: str, words: str) -> None:
    path = tmp_path / "rig.yaml"
    path.write_text(body)
    with pytest.raises(ConfigError) as info:
        load_tunnel_config(path)
    assert str(path) in str(info.value) and f"'{key}'" in str(info.value) and words in str(info.value)
