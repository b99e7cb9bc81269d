"""The accuracy benchmark of Raynaud & Mulleners (2024, section 3) on flagtrack's simulator.

``plan`` defines presets, methods and the simulated recordings of each part; ``evaluate`` runs one
recording (simulate, read the file back, track, compare with the truth); ``runner`` runs them on a
process pool; ``tables``, ``figures`` and ``report`` write the results folder. The command is
``flagtrack bench accuracy`` (docs/benchmark.md).
"""
