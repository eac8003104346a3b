"""Fingers that touch props and the body (Bitan, Jörg, Kraus 2016, seed 002).

Props as colliders (:mod:`.colliders`) with exact signed distances (:mod:`.proximity`),
finger capsules from the rig (:mod:`.finger_geometry`), a clearance test that cannot
miss a contact (:mod:`.clearance`), the largest curl of each finger chain that stays
clear (:mod:`.ik`), a bound-constrained smoother (:mod:`.smoothing`), and the whole
correction with its guarantee (:mod:`.correction`).
"""
