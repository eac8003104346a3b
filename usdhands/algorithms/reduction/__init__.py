"""Finger DOF reduction by range and RMS deviation (Jörg, O'Sullivan 2009).

The steps (:mod:`.reduce`, entry point ``reduce_curves``) and the model that rebuilds a
full hand from its controlling curves (:mod:`.model`).
"""
