"""The composition root: the one place that knows the whole rig.

- :mod:`.table`: the service table, every service described once (its name, sections, bus keys,
  checks, preparation, how it is built);
- :mod:`.sections`, :mod:`.config`: the rig file (``RigConfig``), read and checked against the
  table before anything opens;
- :mod:`.access`: the bus's access-control rules, made from the table;
- :mod:`.camera`, :mod:`.context`, :mod:`.build`, :mod:`.prepare`: the camera adapter, the table's
  steps and what they get; the services built (opening nothing) and prepared;
- :mod:`.run`: open the bus, start the services in table order, run them, report how the run ended.

Kept import-free so ``flagtrack --help`` stays fast: import the submodule you need (:mod:`.table`
imports only the standard library).
"""
