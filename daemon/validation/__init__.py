"""Independent validation against a point sensor (paper section 4, figure 5c-g): per-point sync and
comparison (:mod:`.point`), gathering from the bus and files (:mod:`.collect`), figures
(:mod:`.figures`) and whole runs (:mod:`.run`, ``flagtrack validate``). See docs/sensor.md."""
