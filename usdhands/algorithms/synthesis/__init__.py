"""Finger synthesis from wrist motion (Jörg, Hodgins, Safonova 2012).

Segmentation by wrist speed, the finger-motion database, DTW segment costs, the motion
graph of transitions, stitching, and the leave-one-out / held-out evaluation. The entry
point is :func:`usdhands.algorithms.synthesis.synthesize.synthesize_clip`.
"""
