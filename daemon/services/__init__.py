"""Services of the daemon (camera, tracker, flag state, recorder, viewer, sensor, supervisor) and the runner
that hosts them; which of them a rig runs, and how each is built, is the table of ``daemon/rig/table.py``."""
