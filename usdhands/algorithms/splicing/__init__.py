"""Hand/body splicing by two-pass dynamic time warping (Majkowska, Zordan, Faloutsos 2006).

Markers from joints (:mod:`.markers`), the distances of eq. 6-9 (:mod:`.costs`), and the
passes, merge and finger transfer (:mod:`.splice`, entry point ``splice_clips``). The
banded DTW with user constraints is shared: :mod:`usdhands.algorithms.dtw`.
"""
