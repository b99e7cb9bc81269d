"""The simulated tunnel controller on a real pseudo-terminal, as one fixture (a plugin of every test).

``sim`` is a :class:`SimulatedTunnel` with :data:`RIG_SIM` (a controller that follows set-points at
once). A test module that needs another controller overrides the ``sim_params`` fixture (and, for a
Modbus drive, ``sim_modbus_map``); ``sim`` itself is defined here only.
"""

from __future__ import annotations

from collections.abc import Iterator

import pytest

from flagtrack.drivers.tunnel.modbus import ModbusMap
from flagtrack.drivers.tunnel.sim_model import SimParams
from flagtrack.drivers.tunnel.simulated import SimulatedTunnel

RIG_SIM = SimParams(tau_s=0.05, ramp_mps2=100.0, watchdog_s=1.0)
"""Set-points reached within a tenth of a second: for commands and services that only need a tunnel."""
SWEEP_SIM = SimParams(tau_s=0.1, ramp_mps2=6.0, watchdog_s=1.0)
"""A controller that ramps, as the simulated rig's (:data:`tests.fakes.rig.SWEEP_TUNNEL`): for sweeps."""
FAST_SIM = SimParams(tau_s=0.02, ramp_mps2=500.0, max_speed_mps=12.0, watchdog_s=1.0, tick_s=0.002)
"""The protocol drivers' tests: set-points reached at once, a fine tick."""


@pytest.fixture
def sim_params() -> SimParams:
    """The parameters of ``sim``'s controller; a module overrides this fixture to change them."""
    return RIG_SIM


@pytest.fixture
def sim_modbus_map() -> ModbusMap:
    """The register map of ``sim``'s controller when it speaks Modbus."""
    return ModbusMap()


@pytest.fixture
def sim(sim_params: SimParams, sim_modbus_map: ModbusMap) -> Iterator[SimulatedTunnel]:
    """A simulated tunnel controller answering on a real pty (``sim.port``), stopped after the test."""
    if sim_params.protocol == "modbus":
        pytest.importorskip("pymodbus")
    with SimulatedTunnel(sim_params, sim_modbus_map) as tunnel:
        yield tunnel
