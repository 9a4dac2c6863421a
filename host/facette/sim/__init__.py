"""facette.sim: the simulated rig (sensor model, DNG writer, rig simulator)."""
