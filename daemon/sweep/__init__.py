"""Sweep runs: plans (generators of steps), the append-only JSON-lines run log, resume
bookkeeping, summary CSV and figures. The service that executes plans lives in ``services``."""
