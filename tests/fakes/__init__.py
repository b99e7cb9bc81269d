"""Fake camera SDK modules for tests (``neuromorphic_drivers``, ``metavision_hal``, ``dv_processing``).

They are imported under the real modules' names: the fixtures of :mod:`tests.fakes.fixtures` put this
folder first on ``sys.path`` and remove the fakes from ``sys.modules`` afterwards.
"""
