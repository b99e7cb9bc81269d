"""Sweep runs: plans (generators of steps), the runner that carries them out in a safe session
(steps, point validity, retries, resume, safe stop; no bus: the supervisor service wires it), the
append-only JSON-lines run log, resume bookkeeping, summary CSV and figures."""
