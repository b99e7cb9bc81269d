"""The composition root: the one place that knows the whole rig.

- :mod:`.config`: the rig file (``RigConfig``), read and checked before anything opens;
- :mod:`.build`: the services it asks for, each given its own section and the bus;
- :mod:`.run`: open the bus, run the services, report how the run ended.

Kept import-free so ``flagtrack --help`` stays fast: import the submodule you need.
"""
