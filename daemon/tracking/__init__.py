"""One tracking set-up for every command and service.

- :mod:`.section`: the ``tracker:`` YAML section (``TrackingConfig``);
- :mod:`.setup`: that section plus its calibration turned into a tracker factory, units and the
  attributes every centreline file carries (``reconstruct``, ``up``, the recorder, validation, batch);
- :mod:`.offline`: a recording streamed through a tracker into a centreline file.
"""
