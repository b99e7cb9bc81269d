"""The digital twin: flag kinematics, flutter model, laser-line rendering and event-camera simulation."""
