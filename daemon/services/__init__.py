"""Services of the daemon (camera, tracker, recorder, viewer, supervisor) and the runner that hosts them."""
