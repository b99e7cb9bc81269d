"""The engine of ``flagtrack batch``: many recordings or sweep runs processed at once, on a local process
pool or a Dask cluster, idempotently (see docs/batch.md).

``inputs`` turns the command line into recordings and output names, ``stamp`` records and checks what
an output was made from, ``tasks`` is what a worker runs (paths in, one row out), ``executor`` is the
local pool or Dask behind one futures interface, ``campaign`` drives a batch, ``rows``, ``progress``
and ``figures`` report it.
"""
