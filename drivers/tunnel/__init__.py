"""Wind-tunnel drivers: one small interface (:class:`WindTunnel`), the safety layer
(:class:`SafeTunnel`), an ASCII line-protocol fan controller, a Modbus RTU drive, and a simulated
tunnel that speaks both protocols on a pseudo-terminal.

Import what you need from the submodules (``flagtrack.drivers.tunnel.safe``, ``.ascii``,
``.modbus``, ``.simulated``, ``.config``); this package imports nothing heavy.
"""
